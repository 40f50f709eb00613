#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "cluster.h"
#include "commands.h"
#include "core/errors.h"
#include "database.h"
#include "distributed_render.h"
#include "io/image_io.h"
#include "output_checks.h"
#include "progress.h"
#include "scene_files.h"
#include "render/renderer.h"
#include "scene/scene_loader.h"

namespace fluorosim::app {
namespace fs = std::filesystem;
namespace {

std::atomic<bool> gCancel{false};
extern "C" void onSignal(int) { gCancel.store(true); }

struct RenderArgs {
    std::string scene, output;
    std::optional<int> spp;
    int threads = 0;
    std::optional<uint64_t> seed;
    std::string fluorescence;
    double checkpointSeconds = 60;
    std::string preview = "total";  // which light the PNG shows: total, elastic or fluorescent
};

void checkWritable(const fs::path& out) {
    requireWritableFolder(out);  // now rather than after an hour of rendering
    if (out.extension() != ".exr") throw ConfigError(out.string() + ": output must be an .exr file");
}

// Reinhard's key value: maps the log-average luminance to 0.18, so small bright emitters do not
// darken the preview.
double autoExposure(const ExrImage& img) {
    double logSum = 0;
    size_t count = 0;
    for (size_t p = 0; p + 2 < img.rgb.size(); p += 3) {
        const double y = 0.2126 * img.rgb[p] + 0.7152 * img.rgb[p + 1] + 0.0722 * img.rgb[p + 2];
        if (!(y > 0) || !std::isfinite(y)) continue;
        logSum += std::log(y);
        ++count;
    }
    return count ? 0.18 / std::exp(logSum / static_cast<double>(count)) : 1.0;
}

// Writes the EXR and the PNG preview next to it; returns the preview's path.
fs::path writeOutputs(const fs::path& out, const Film& film, const Scene& scene, int sppDone, const RenderSummary* summary,
                      const std::string& preview) {
    ExrImage img = film.image(sppDone);
    img.attributes["fluorosim.spp"] = std::to_string(sppDone);
    img.attributes["fluorosim.seed"] = std::to_string(scene.render.seed);
    img.attributes["fluorosim.wavelengthRange"] = std::to_string(scene.spectral.lambdaMin) + "-" + std::to_string(scene.spectral.lambdaMax) + " nm";
    if (summary) img.attributes["fluorosim.nonFiniteSamples"] = std::to_string(summary->nonFiniteSamples);
    // Write to a temporary name first so an interrupted write never destroys a finished image.
    const fs::path tmp = out.string() + ".partial.exr";
    writeExr(tmp.string(), img);
    fs::rename(tmp, out);
    fs::path png = out;
    png.replace_extension(".png");
    const std::vector<float>* rgb = &img.rgb;
    for (const RgbLayer& l : img.rgbLayers)
        if (l.prefix == preview) rgb = &l.rgb;
    ExrImage shown;
    shown.rgb = *rgb;
    writePngPreview(png.string(), img.width, img.height, *rgb, autoExposure(shown));
    return png;
}

double nullPerReal(const PathStats& st) {
    const double real = static_cast<double>(st.scatteringEvents + st.absorptionEvents);
    return real > 0 ? (static_cast<double>(st.tentativeCollisions) - real) / real : 0.0;
}

void runRender(const RenderArgs& a) {
    const fs::path out = a.output;
    if (!(a.checkpointSeconds > 0)) throw ConfigError("--checkpoint-seconds: must be positive, got " + std::to_string(a.checkpointSeconds));
    if (cluster::isRoot()) checkWritable(out);  // under MPI only the root writes
    const spectra::Database db;
    Scene scene = loadSceneFile(a.scene, db);
    if (cluster::isRoot())
        for (const std::string& w : scene.warnings) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());
    if (a.seed) scene.render.seed = *a.seed;
    if (!a.fluorescence.empty()) {
        const auto model = fluorescenceModelFromName(a.fluorescence);
        if (!model) throw ConfigError("--fluorescence: expected full, paper or none, got \"" + a.fluorescence + "\"");
        scene.render.fluorescence = *model;
    }
    RenderOptions opt;
    opt.spp = a.spp.value_or(scene.render.spp);
    opt.validate();
    opt.threads = a.threads;
    opt.seed = scene.render.seed;
    // One sample per pixel per pass: Ctrl-C then waits at most one pass, and checkpoints stay fresh.
    opt.sppPerPass = 1;
    opt.cancel = &gCancel;
    Film film(scene.camera.width, scene.camera.height, scene.spectral.lambdaMin, scene.spectral.lambdaMax, scene.spectral.binWidth, db.cie1931(),
              FluorescencePlan(scene).active());
    std::signal(SIGINT, onSignal);
    std::signal(SIGTERM, onSignal);
    if (!cluster::isRoot()) return serveBands(scene, film, opt);  // MPI: render the bands rank 0 hands out
    ProgressBar bar("render");
    opt.progress = [&](double f) { bar.update(f); };
    auto lastCheckpoint = std::chrono::steady_clock::now();
    opt.passFinished = [&](const Film& f, int sppDone) {
        const auto now = std::chrono::steady_clock::now();
        if (sppDone < opt.spp && std::chrono::duration<double>(now - lastCheckpoint).count() > a.checkpointSeconds) {
            writeOutputs(out, f, scene, sppDone, nullptr, a.preview);
            lastCheckpoint = now;
        }
    };
    const RenderSummary s = renderOnCluster(scene, film, opt);
    bar.finish();
    if (s.sppCompleted == 0 && cluster::size() > 1)
        throw Interrupted("render interrupted; under mpirun the image is written only once every band is done, so nothing was written");
    if (s.sppCompleted == 0) throw Error("interrupted before the first pass finished; nothing written");
    const fs::path png = writeOutputs(out, film, scene, s.sppCompleted, &s, a.preview);
    const double bounces = static_cast<double>(s.stats.scatteringEvents + s.stats.surfaceBounces) / std::max<double>(1.0, static_cast<double>(s.stats.paths));
    const nlohmann::json summary = {{"image", out.string()},
                                    {"preview", png.string()},
                                    {"spp", s.sppCompleted},
                                    {"seconds", s.seconds},
                                    {"paths", s.stats.paths},
                                    {"mean_path_vertices", bounces},
                                    {"non_finite_samples", s.nonFiniteSamples},
                                    {"truncated_paths", s.stats.truncated},
                                    {"fluorescence", fluorescenceModelName(scene.render.fluorescence)},
                                    {"fluorescence_branches", s.stats.fluorescenceBranches},
                                    {"tentative_collisions", s.stats.tentativeCollisions},
                                    {"scattering_events", s.stats.scatteringEvents},
                                    {"surface_bounces", s.stats.surfaceBounces},
                                    // Null (and branch-process) collisions per real one: the cost of the majorants.
                                    {"null_per_real_collision", nullPerReal(s.stats)},
                                    {"cancelled", s.cancelled}};
    std::printf("%s\n", summary.dump().c_str());
    std::fflush(stdout);
    std::fprintf(stderr, "fluorosim: wrote %s and %s (%d spp in %.1f s)%s\n", out.string().c_str(), png.string().c_str(),
                 s.sppCompleted, s.seconds, s.cancelled ? " -- interrupted, finished passes kept" : "");
    if (s.nonFiniteSamples > 0)
        std::fprintf(stderr, "fluorosim: warning: %llu non-finite samples were dropped\n", static_cast<unsigned long long>(s.nonFiniteSamples));
    if (s.cancelled) throw Interrupted("render interrupted after " + std::to_string(s.sppCompleted) + " spp (image written)");
}

}  // namespace

void addRenderCommand(CLI::App& app) {
    auto args = std::make_shared<RenderArgs>();
    CLI::App* cmd = app.add_subcommand("render", "Render a scene to a spectral OpenEXR image and a PNG preview");
    cmd->add_option("scene", args->scene, "Scene file (JSON)")->required();
    cmd->add_option("-o,--output", args->output, "Output .exr (a .png preview is written next to it)")->required();
    cmd->add_option("--spp", args->spp, "Samples per pixel (default: the scene's)");
    cmd->add_option("--threads", args->threads, "Threads (0 = all cores)");
    cmd->add_option("--seed", args->seed, "Random seed (default: the scene's)");
    cmd->add_option("--fluorescence", args->fluorescence,
                    "Fluorescence model: full (unbiased, default), paper (Abdellah et al.: one event, direct light) or none");
    cmd->add_option("--checkpoint-seconds", args->checkpointSeconds, "Write the image every this many seconds");
    cmd->add_option("--preview", args->preview,
                    "What the PNG preview shows: total (default), elastic or fluorescent (the EXR always has all three)")
        ->check(CLI::IsMember({"total", "elastic", "fluorescent"}));
    cmd->callback([args] { runRender(*args); });
}

}  // namespace fluorosim::app
