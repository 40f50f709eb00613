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
                              {"max_spp", o.noiseRatio ? o.maxSpp : 0}};
    return j.dump();
}

double median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    return v[v.size() / 2];
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
    PathStats stats;
    double seconds = 0, largest = 0, largestOverPixel = 0, computedSum = 0, pathSum = 0, pooledSum = 0, computedSeconds = 0, pathSeconds = 0;
    std::vector<double> pathRel;       // relative standard errors over the brightest pixels
    std::vector<double> mcOverCamera;  // MC variance over the camera's noise variance, brightest pixels
    uint64_t pathSamples = 0, pilotSamples = 0, pixels = 0, computedPoints = 0, nonFinite = 0;
    optics::UnscatteredTimings computedTimings;  // summed over planes
    const double darkElectrons = m.detector.darkCurrentElectronsPerS * m.detector.exposureS;
    cb.planeDone = [&](size_t slot, int plane, const optics::PlaneImage& image) {
        checkpoint->append(slot, plane, image);
        stats.add(image.stats);
        seconds += image.seconds;
        largest = std::max(largest, image.largestSample);
        largestOverPixel = std::max(largestOverPixel, image.largestSampleOverPixel);
        computedSum += image.computedElectrons;
        pathSum += image.pathElectrons;
        pooledSum += image.pooledElectrons;
        computedSeconds += image.computedSeconds;
        pathSeconds += image.pathSeconds;
        computedPoints += image.computedPoints;
        computedTimings.lattice += image.computedTimings.lattice;
        computedTimings.transmittances += image.computedTimings.transmittances;
        computedTimings.gains += image.computedTimings.gains;
        computedTimings.projection += image.computedTimings.projection;
        computedTimings.kernelThreadSeconds += image.computedTimings.kernelThreadSeconds;
        nonFinite += image.nonFiniteSamples;
        pathSamples += image.pathSamples;
        pilotSamples += image.pilotSamples;
        pixels += image.electrons.size();
        std::vector<double> sorted = image.electrons;
        std::sort(sorted.begin(), sorted.end());
        const double cut = sorted[static_cast<size_t>(0.9 * (sorted.size() - 1))];
        for (size_t i = 0; i < image.electrons.size(); ++i)
            if (image.electrons[i] >= cut) {
                mcOverCamera.push_back(sqr(image.stderrElectrons[i]) /
                                       (std::max(0.0, image.electrons[i]) + darkElectrons + sqr(m.detector.readNoiseElectrons)));
                if (image.electrons[i] > 0) pathRel.push_back(image.stderrElectrons[i] / image.electrons[i]);
            }
        double signal = 0;
        for (double e : image.electrons) signal += e;
        if (!(signal > 0))
            std::fprintf(stderr, "fluorosim: warning: channel \"%s\", plane %d: no signal (the sheet or the focal plane misses the labelled volume)\n",
                         m.channels[stack.channels[slot]].name.c_str(), plane);
    };
    const bool finished = acquireStackOnCluster(scene, m, stack, o, cb);
    bar.finish();

    const int planes = stack.completePlanes();
    const std::string description = "Fluorosim acquisition of " + a.scene + ", " + std::to_string(o.spp) + " spp, seed " + std::to_string(o.seed) +
                                    (finished ? "" : " (interrupted: " + std::to_string(planes) + " of " + std::to_string(stack.planes) + " planes)");
    if (planes > 0) optics::writeStackFiles(out, stack, m, planes, description);
    if (!finished) {
        throw Interrupted("acquire interrupted with " + std::to_string(planes) + " of " + std::to_string(stack.planes) +
                          " planes complete" + (planes > 0 ? " (written)" : "") + "; finished planes are kept in " + checkpointPath.string() +
                          ", continue with --resume");
    }
    fs::remove(checkpointPath);
    float maxE = 0;
    size_t saturated = 0, saturatedOutliers = 0;  // above the full well; of those, within 4 standard errors of it
    for (size_t i = 0; i < stack.expected.size(); ++i) {
        const float e = stack.expected[i];
        maxE = std::max(maxE, e);
        if (e > m.detector.fullWellElectrons) {
            ++saturated;
            if (e - 4 * stack.stderrElectrons[i] < m.detector.fullWellElectrons) ++saturatedOutliers;
        }
    }
    const double vertices = double(stats.scatteringEvents + stats.surfaceBounces) / std::max<double>(1.0, double(stats.paths));
    const nlohmann::json summary = {{"stack", out.counts.string()},
                                    {"expected", out.expected.string()},
                                    {"stderr", out.stderrElectrons.string()},
                                    {"preview", out.preview.string()},
                                    {"planes", stack.planes},
                                    {"channels", stack.channels.size()},
                                    {"width", stack.width},
                                    {"height", stack.height},
                                    {"pixel_size_um", m.pixelSizeMm() * 1e3},
                                    {"z_step_um", m.stack.stepMm * 1e3},
                                    {"spp", o.spp},
                                    {"estimator", optics::estimatorName(o.estimator)},
                                    {"computed_electrons_fraction", computedSum / std::max(1e-300, computedSum + pathSum)},
                                    {"pooled_electrons_fraction", pooledSum / std::max(1e-300, computedSum + pathSum)},
                                    {"computed_seconds", computedSeconds},
                                    {"computed_points", computedPoints},
                                    // Where the computed part's time went: S and the transmittances once per
                                    // channel, then per plane the sheet's gains and the projection.
                                    {"computed_timings",
                                     {{"lattice_seconds", computedTimings.lattice},
                                      {"transmittance_seconds", computedTimings.transmittances},
                                      {"gain_seconds", computedTimings.gains},
                                      {"projection_seconds", computedTimings.projection},
                                      {"kernel_thread_seconds", computedTimings.kernelThreadSeconds}}},
                                    {"path_thread_seconds", pathSeconds},
                                    {"median_relative_stderr_top10", median(pathRel)},
                                    {"non_finite_samples", nonFinite},
                                    {"largest_sample_over_pixel", largestOverPixel},
                                    {"noise_ratio_target", o.noiseRatio ? nlohmann::json(*o.noiseRatio) : nlohmann::json(nullptr)},
                                    // The standard errors' own estimate (heavy tails make it optimistic;
                                    // scripts/noise-vs-time.sh measures with two seeds).
                                    {"median_mc_over_camera_variance_top10", median(mcOverCamera)},
                                    {"mean_path_spp", double(pathSamples) / std::max<double>(1.0, double(pixels))},
                                    {"pilot_paths", pilotSamples},
                                    {"seed", o.seed},
                                    {"ranks", cluster::size()},
                                    {"seconds", seconds},
                                    {"paths", stats.paths},
                                    {"mean_path_vertices", vertices},
                                    {"truncated_paths", stats.truncated},
                                    {"largest_sample_electrons", largest},
                                    {"max_expected_electrons", maxE},
                                    {"full_well_electrons", m.detector.fullWellElectrons}};
    std::printf("%s\n", summary.dump().c_str());
    // An adaptive run that stopped at its path limit says so, with the noise it reached.
    const double mcOverCameraMedian = median(mcOverCamera);
    if (o.noiseRatio && mcOverCameraMedian > sqr(*o.noiseRatio) * 1.5)
        std::fprintf(stderr,
                     "fluorosim: warning: noise target %.3g missed: the Monte Carlo error over the camera's noise is %.3g (median over the "
                     "brightest 10 %% of pixels, as a ratio of standard deviations), at %.3g paths per pixel on average (--max-spp %d)\n",
                     *o.noiseRatio, std::sqrt(mcOverCameraMedian), double(pathSamples) / std::max<double>(1.0, double(pixels)), o.maxSpp);
    if (saturated > 0)
        std::fprintf(stderr,
                     "fluorosim: warning: %zu of %zu pixels expect more than the full well (%.3g e-; brightest %.3g e-): the camera saturates "
                     "there%s\n",
                     saturated, stack.expected.size(), m.detector.fullWellElectrons, double(maxE),
                     saturatedOutliers == saturated ? "; each is within 4 Monte Carlo standard errors of the full well (rare large samples: "
                                                      "more paths, not less exposure, may be what they need)"
                                                    : "");
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
                    "camera's noise of the expected signal, sqrt(signal + dark + read^2), decided from separate pilot paths");
    cmd->add_option("--max-spp", a->maxSpp, "Adaptive sampling: most paths per pixel (default 4096)");
    cmd->add_option("--seed", a->seed, "Random seed (default: the scene's)");
    cmd->add_option("--threads", a->threads, "Threads (0 = all cores)");
    cmd->add_option("--channels", a->channels, "Channels to acquire, by name (default: all)")->delimiter(',');
    cmd->add_flag("--resume", a->resume, "Continue an interrupted run from STACK.checkpoint (same scene and options)");
    cmd->callback([a] { runAcquire(*a); });
}

}  // namespace fluorosim::app
