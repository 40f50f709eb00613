// `fluorosim acquire SCENE.json -o STACK.ome.tif`: a light-sheet z-stack through optics' acquisition
// API. The scene's "microscope" block (docs/optics.md) describes objective, detector, channels and
// stack. Every finished plane goes to STACK.checkpoint at once; SIGINT or SIGTERM stops within a row,
// writes the complete planes, and `--resume` continues to the same result as an uninterrupted run.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>

#include "cluster.h"
#include "commands.h"
#include "core/errors.h"
#include "core/math.h"
#include "core/units.h"
#include "optics/acquire_request.h"
#include "optics/setup_checks.h"
#include "distributed_acquire.h"
#include "optics/acquisition.h"
#include "optics/acquisition_summary.h"
#include "optics/stack_files.h"
#include "core/output_checks.h"
#include "progress.h"
#include "optics/scene_files.h"

namespace fluorosim::app {
namespace fs = std::filesystem;
namespace {

std::atomic<bool> gCancel{false};
extern "C" void onAcquireSignal(int) { gCancel.store(true); }

struct AcquireArgs : optics::AcquireRequest {
    std::string scene, output;
    bool resume = false;
};

// Everything that determines the stack, so that --resume never mixes two different runs.
std::string fingerprint(const AcquireArgs& a, const optics::Microscope& m, const optics::Stack& stack, const optics::AcquireOptions& o) {
    std::ifstream f(a.scene, std::ios::binary);
    std::ostringstream text;
    text << f.rdbuf();
    uint64_t h = 0xcbf29ce484222325ULL;
    for (unsigned char c : text.str()) h = (h ^ c) * 0x100000001b3ULL;
    nlohmann::json channels = nlohmann::json::array();
    for (size_t c : stack.channels) channels.push_back(m.channels[c].name);
    const nlohmann::json j = {{"scene_fnv1a", h}, {"seed", o.seed}, {"spp", o.spp}, {"planes", m.stack.planes}, {"step_mm", m.stack.stepMm},
                              {"channels", channels}, {"estimator", optics::estimatorName(o.estimator)},
                              {"noise_ratio", o.noiseRatio.value_or(0.0)},
                              {"max_spp", o.noiseRatio ? o.maxSpp : 0}, {"exposure_s", m.detector.exposureS},
                              {"field_photons", o.field.photons}, {"field_margin_um", o.field.marginUm.value_or(-1)}, {"field_reach_um", o.field.reachUm.value_or(-1)},
                              {"field_diffuse_um", o.field.diffuseUm.value_or(-1)},
                              {"emission_photons", o.emission.photons ? static_cast<int64_t>(*o.emission.photons) : int64_t(-1)},
                              {"emission_photons_per_pixel", o.emission.photonsPerPixel}};
    return j.dump();
}

void runAcquire(const AcquireArgs& a) {
    optics::checkAcquireRequest(a);
    const spectra::Database db;
    const Scene scene = optics::loadSceneFile(a.scene, db);
    if (cluster::isRoot())  // under MPI every rank loads the scene; one of them speaks
        for (const std::string& w : scene.warnings) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());
    optics::Microscope m = optics::Microscope::fromScene(scene, db);
    if (cluster::isRoot())
        for (const std::string& w : m.warnings) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());
    optics::AcquireOptions o = optics::applyAcquireRequest(a, scene, m);
    o.cancel = &gCancel;

    const std::vector<size_t> selected = m.selectChannels(a.channels, "--channels");
    const std::vector<std::string> setupWarnings = optics::checkSetup(scene, m, selected);
    if (!cluster::isRoot()) {  // MPI: the other ranks render the planes that rank 0 hands out
        std::signal(SIGINT, onAcquireSignal);
        std::signal(SIGTERM, onAcquireSignal);
        return servePlanes(scene, m, o);
    }

    const optics::StackOutputs out = optics::StackOutputs::forStack(a.output);
    requireWritableFolder(out.counts);
    for (size_t c : selected)
        for (const std::string& w : m.channels[c].warnings) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());
    for (const std::string& w : setupWarnings) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());
    optics::Stack stack = optics::emptyStack(m, selected);
    const fs::path checkpointPath = fs::path(a.output).replace_extension("").replace_extension(".checkpoint");
    const std::string print = fingerprint(a, m, stack, o);
    std::optional<optics::StackCheckpoint> checkpoint;
    if (a.resume) {
        checkpoint = optics::StackCheckpoint::resume(checkpointPath, print, stack, m, o.seed);
        size_t done = 0;
        for (bool d : stack.done) done += d;
        std::fprintf(stderr, "fluorosim: resuming %s: %zu of %zu planes already done\n", checkpointPath.string().c_str(), done, stack.done.size());
    } else {
        if (fs::exists(checkpointPath))
            std::fprintf(stderr, "fluorosim: warning: starting over; %s from an earlier run is replaced (use --resume to continue it)\n",
                         checkpointPath.string().c_str());
        checkpoint.emplace(checkpointPath, print);
    }

    std::signal(SIGINT, onAcquireSignal);
    std::signal(SIGTERM, onAcquireSignal);
    ProgressBar bar("acquire");
    optics::StackCallbacks cb;
    cb.progress = [&](double f) { bar.update(f); };
    optics::AcquisitionSummary report(m, stack, o);
    cb.planeDone = [&](size_t slot, int plane, const optics::PlaneImage& image) {
        checkpoint->append(slot, plane, image);
        if (const std::string w = report.addPlane(slot, plane, image); !w.empty()) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());
    };
    const bool finished = acquireStackOnCluster(scene, m, stack, o, cb);
    bar.finish();

    const int planes = stack.completePlanes();
    // --exposure auto: the stack scaled to the exposure that puts its brightest pixel at the asked fraction
    // of the full well (exact: photoelectrons scale with the exposure), before it is written and checked.
    std::optional<optics::AutoExposure> chosen;
    if (const optics::ExposureRequest e = optics::parseExposure(a.exposure); e.autoFraction && planes > 0) {
        const double before = m.detector.exposureS;
        chosen = optics::autoExpose(stack, m, *e.autoFraction, o.seed);
        std::fprintf(stderr,
                     "fluorosim: exposure auto: %.4g ms (the scene's %.4g ms x %.4g) puts the brightest pixel's expected signal (%.4g e-) at "
                     "%.3g of the full well (%.4g e-)\n",
                     chosen->exposureS * 1e3, before * 1e3, chosen->factor, chosen->brightestElectrons * chosen->factor, chosen->fraction,
                     m.detector.fullWellElectrons);
    }
    const std::string description = "Fluorosim acquisition of " + a.scene + ", " + std::to_string(o.spp) + " spp, seed " + std::to_string(o.seed) +
                                    (finished ? "" : " (interrupted: " + std::to_string(planes) + " of " + std::to_string(stack.planes) + " planes)");
    if (planes > 0) optics::writeStackFiles(out, stack, m, planes, description);
    if (!finished) {
        throw Interrupted("acquire interrupted with " + std::to_string(planes) + " of " + std::to_string(stack.planes) +
                          " planes complete" + (planes > 0 ? " (written)" : "") + "; finished planes are kept in " + checkpointPath.string() +
                          ", continue with --resume");
    }
    fs::remove(checkpointPath);
    nlohmann::json summary = {{"stack", out.counts.string()},
                              {"expected", out.expected.string()},
                              {"stderr", out.stderrElectrons.string()},
                              {"preview", out.preview.string()},
                              {"estimator", optics::estimatorName(o.estimator)},
                              {"seed", o.seed}};
    for (const optics::AcquisitionSummary::Entry& e : report.entries(stack, m, chosen, cluster::size())) {
        const nlohmann::json value = e.null ? nlohmann::json(nullptr) : e.count ? nlohmann::json(static_cast<int64_t>(e.value)) : nlohmann::json(e.value);
        if (e.group.empty()) summary[e.name] = value;
        else summary[e.group][e.name] = value;
    }
    std::printf("%s\n", summary.dump().c_str());
    for (const std::string& w : report.warnings(stack, m)) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());
}

}  // namespace

void addAcquireCommand(CLI::App& app) {
    auto a = std::make_shared<AcquireArgs>();
    CLI::App* cmd = app.add_subcommand("acquire", "Simulate a light-sheet z-stack and write it as OME-TIFF");
    cmd->add_option("scene", a->scene, "Scene file with a \"microscope\" block")->required();
    cmd->add_option("-o,--output", a->output,
                    "Output STACK.ome.tif (STACK.expected.ome.tif, STACK.stderr.ome.tif and STACK.preview.png are written next to it)")
        ->required();
    cmd->add_option("--planes", a->planes, "Number of planes (default: the scene's stack)");
    cmd->add_option("--step", a->step, "Distance between planes with a unit, e.g. 2um");
    cmd->add_option("--spp", a->spp, "Path samples per pixel");
    cmd->add_option("--estimator", a->estimator,
                    "split (default: the unscattered image computed, paths for the scattered light) or path (every sample a full path: "
                    "the reference)");
    // Removed with the sampled direct part; refused with a message rather than CLI11's generic one.
    cmd->add_option_function<std::string>("--direct-spp", [](const std::string&) {
           throw ConfigError("--direct-spp: removed: the split estimator now computes the unscattered image (no samples); "
                             "--spp sets the paths for the scattered light");
       })->group("");
    cmd->add_option("--noise-ratio", a->noiseRatio,
                    "Adaptive sampling: paths per pixel (--spp at least) until the Monte Carlo standard error is at most this times the "
                    "camera's noise of the expected signal, sqrt(signal + dark + read^2), decided from separate pilot paths (first on every fourth pixel across and down, elsewhere only near those that ask for more); and the traced "
                    "scattered emission's photons (up to 32 times --emission-photons) until their median variance over the brightest tenth "
                    "and 1 % is at most half the target's, and, decided from a pilot of a quarter of those photons, the excitation field's "
                    "(from 4 times --field-photons where the target is at most 1, up to 16 times it) until its variance in the computed and "
                    "traced image over the brightest tenth and 1 % (its squared half difference over 0.455, the median of a "
                    "one-degree-of-freedom chi-square) is at most half the target's");
    cmd->add_option("--max-spp", a->maxSpp, "Adaptive sampling: most paths per pixel (default 4096)");
    cmd->add_option("--field-photons", a->fieldPhotons,
                    "Split estimator: photons per beam line and plane of the excitation field, which computes the scattered excitation "
                    "instead of sampling it with paths (default 200000; 0: paths only)");
    cmd->add_option("--field-margin-um", a->fieldMarginUm,
                    "Split estimator: how far (um) the excitation field reaches along the focal plane beyond the computed region; there the "
                    "traced photons carry the sheet-lit dye's emission, which reaches the image only by scattering (default 100, or 0.15 mm^2 "
                    "times the tissue's reduced scattering coefficient where that is more)");
    cmd->add_option("--field-reach-um", a->fieldReachUm,
                    "Split estimator: how far (um) from the focal plane the excitation field reaches, on 4 um nodes beyond its fine 20 um; "
                    "the dye lit there by scattered light is the traced photons' (default 120, or as the margin where that is more)");
    cmd->add_option("--field-diffuse-um", a->fieldDiffuseUm,
                    "Split estimator: node spacing (um) of the excitation field's diffuse light (photons that have scattered 10 times), "
                    "over its whole reach (default a tenth of the tissue's transport length 1/mu_s', within [4, 50]; 0: none)");
    cmd->add_option("--emission-photons", a->emissionPhotons,
                    "Split estimator: photons per plane and channel that trace the computed emission's scattered light forward and image "
                    "their vertices, where the tissue scatters the detected light (default 4 per pixel: 262144 on a 256 x 256 plane; 0: camera paths "
                    "carry it)");
    cmd->add_option("--emission-track-um", a->emissionTrackUm,
                    "Split estimator: within this distance (um) of the focal plane the traced photons' scattering is imaged at points along "
                    "their flights, weighed by the scattering coefficient (a track-length estimator, where the scattering coefficient times "
                    "the slab's thickness is at most 0.25), instead of where they scatter (default 20; 0: at every scattering)");
    cmd->add_option("--seed", a->seed, "Random seed (default: the scene's)");
    cmd->add_option("--exposure", a->exposure,
                    "Exposure: a time with a unit (\"20ms\"), or auto[:F]: after the stack is rendered, scale it to the exposure that puts "
                    "its brightest reliable pixel at F of the full well (default 0.5); the summary and the OME metadata give the exposure used");
    cmd->add_option("--threads", a->threads, "Threads (0 = all cores)");
    cmd->add_option("--channels", a->channels, "Channels to acquire, by name (default: all)")->delimiter(',');
    cmd->add_flag("--resume", a->resume, "Continue an interrupted run from STACK.checkpoint (same scene and options)");
    cmd->callback([a] { runAcquire(*a); });
}

}  // namespace fluorosim::app
