#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "cli_checks.h"
#include "cluster.h"
#include "commands.h"
#include "interruption.h"
#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/message.h"
#include "database.h"
#include "distributed_render.h"
#include "io/image_io.h"
#include "core/output_checks.h"
#include "progress.h"
#include "optics/scene_files.h"
#include "render/checkpoint.h"
#include "render/renderer.h"
#include "scene/scene_loader.h"

namespace fluorosim::app {
namespace fs = std::filesystem;
namespace {

// The spp target of a render stopped only by --time: RenderOptions' largest.
constexpr int kMaxTimedSpp = 1 << 24;


struct RenderArgs {
    std::string scene, output;
    std::optional<int> spp;
    int threads = 0;
    std::optional<uint64_t> seed;
    std::string fluorescence;
    std::string integrator;         // overrides the scene's render.integrator
    double checkpointSeconds = 60;
    std::string preview = "total";  // which light the PNG shows: total, elastic or fluorescent
    bool resume = false;            // continue from <output>.checkpoint
    std::optional<double> time;     // seconds: render passes until they are spent
};

fs::path checkpointPath(const fs::path& out) { return out.string() + ".checkpoint"; }

// The scene file's text, hashed so that --resume refuses a checkpoint of another scene.
uint64_t sceneHash(const fs::path& file) {
    std::ifstream in(file, std::ios::binary);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    return fnv1a64(text.data(), text.size());
}

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
    const fs::path pngTmp = png.string() + ".partial";
    writePngPreview(pngTmp.string(), img.width, img.height, *rgb, autoExposure(shown));
    fs::rename(pngTmp, png);
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
    if (a.time && !(*a.time > 0 && *a.time <= 1e9))
        throw ConfigError("--time: must lie in (0, 1e9] seconds, got " + messageNumber(*a.time));
    if (a.time && cluster::size() > 1)
        throw ConfigError("--time: each rank would stop at its own pass, so the bands would differ in spp; start it without mpirun");
    if (a.resume && cluster::size() > 1)
        throw ConfigError("--resume: continues a render in one process; start it without mpirun");
    const fs::path ckptPath = checkpointPath(out);
    std::error_code ec;
    if (cluster::isRoot() && a.resume && !fs::exists(ckptPath, ec))
        throw IoError(ckptPath.string() + ": no checkpoint to resume (it is written next to the output while a render runs; "
                                          "run without --resume to start afresh)");
    const spectra::Database db;
    Scene scene = optics::loadSceneFile(a.scene, db);
    if (cluster::isRoot())
        for (const std::string& w : scene.warnings) std::fprintf(stderr, "fluorosim: warning: %s\n", w.c_str());
    if (a.seed) scene.render.seed = *a.seed;
    if (!a.fluorescence.empty()) {
        const auto model = fluorescenceModelFromName(a.fluorescence);
        if (!model) throw ConfigError("--fluorescence: expected full, paper or none, got \"" + excerpt(a.fluorescence) + "\"");
        scene.render.fluorescence = *model;
    }
    if (!a.integrator.empty()) {
        const auto integrator = integratorFromName(a.integrator);
        if (!integrator) throw ConfigError("--integrator: expected path, mnee or light, got \"" + excerpt(a.integrator) + "\"");
        scene.render.integrator = *integrator;
    }
    const int bins = Film::binCount(scene.spectral.lambdaMin, scene.spectral.lambdaMax, scene.spectral.binWidth);
    requireMemory(Film::estimatedBytes(scene.camera.width, scene.camera.height, bins),
                  a.scene + ": /camera/resolution " + std::to_string(scene.camera.width) + "x" + std::to_string(scene.camera.height) +
                      " with " + std::to_string(bins) + " spectral bins (/spectral)");
    Film film(scene.camera.width, scene.camera.height, scene.spectral.lambdaMin, scene.spectral.lambdaMax, scene.spectral.binWidth, db.cie1931(),
              FluorescencePlan(scene).active());
    RenderCheckpoint ckpt;
    ckpt.sceneHash = sceneHash(a.scene);
    ckpt.seed = scene.render.seed;
    ckpt.fluorescence = fluorescenceModelName(scene.render.fluorescence);
    ckpt.integrator = integratorName(scene.render.integrator);
    RenderOptions opt;
    if (a.resume) {
        const RenderCheckpoint prior = readCheckpoint(ckptPath.string(), film);
        if (prior.sceneHash != ckpt.sceneHash)
            throw ConfigError(a.scene + ": differs from the scene that " + ckptPath.string() + " was rendered from");
        if (prior.seed != ckpt.seed)
            throw ConfigError("--seed: " + ckptPath.string() + " was rendered with seed " + std::to_string(prior.seed) + ", got " +
                              std::to_string(ckpt.seed));
        if (prior.fluorescence != ckpt.fluorescence)
            throw ConfigError("--fluorescence: " + ckptPath.string() + " was rendered with \"" + prior.fluorescence + "\", got \"" +
                              ckpt.fluorescence + "\"");
        if (prior.integrator != ckpt.integrator)
            throw ConfigError("--integrator: " + ckptPath.string() + " was rendered with \"" + prior.integrator + "\", got \"" + ckpt.integrator +
                              "\"");
        opt.firstSample = prior.sppDone;
        ckpt.seconds = prior.seconds;
        ckpt.stats = prior.stats;
        opt.spp = a.spp.value_or(prior.sppTarget);
        // A timed render resumed with a new budget continues until it too is spent.
        if (a.time && !a.spp && opt.spp == prior.sppDone) opt.spp = kMaxTimedSpp;
        std::fprintf(stderr, "fluorosim: resuming %s at %d of %d spp\n", ckptPath.string().c_str(), prior.sppDone, opt.spp);
    } else {
        // With --time alone the budget decides where the render stops, not the scene's spp.
        opt.spp = a.spp.value_or(a.time ? kMaxTimedSpp : scene.render.spp);
        if (cluster::isRoot() && fs::exists(ckptPath, ec))
            std::fprintf(stderr, "fluorosim: warning: %s is left from an interrupted render; this render replaces it (--resume continues it)\n",
                         ckptPath.string().c_str());
    }
    ckpt.sppTarget = opt.spp;
    opt.threads = a.threads;
    opt.seed = scene.render.seed;
    opt.timeBudgetSeconds = a.time.value_or(0.0);
    opt.validate();
    // Automatic passes: one sample per pixel on a large image, so checkpoints stay fresh and a cancelled
    // pass loses little; more on a small one, so that a pass is not mostly synchronisation.
    opt.sppPerPass = 0;
    opt.cancel = &installInterruptHandlers();
    if (!cluster::isRoot()) return serveBands(scene, film, opt);  // MPI: render the bands rank 0 hands out
    ProgressBar bar("render");
    auto lastCheckpoint = std::chrono::steady_clock::now();
    const auto start = lastCheckpoint;
    opt.progress = [&](double f) {
        // A timed render is as far along as its budget is spent, unless its spp target comes first.
        if (a.time) f = std::max(f, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() / *a.time);
        bar.update(std::min(f, 1.0));
    };
    const RenderCheckpoint base = ckpt;
    // The image and the checkpoint of the finished passes; `runStats` are this run's.
    auto save = [&](const Film& f, int sppDone, const PathStats& runStats, const RenderSummary* summary) {
        const fs::path png = writeOutputs(out, f, scene, sppDone, summary, a.preview);
        RenderCheckpoint c = base;
        c.sppDone = sppDone;
        c.seconds = base.seconds + std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        c.stats.add(runStats);
        writeCheckpoint(ckptPath.string(), c, f);
        return png;
    };
    opt.passFinished = [&](const Film& f, int sppDone, const PathStats& runStats) {
        const auto now = std::chrono::steady_clock::now();
        if (sppDone < opt.spp && std::chrono::duration<double>(now - lastCheckpoint).count() > a.checkpointSeconds) {
            save(f, sppDone, runStats, nullptr);
            lastCheckpoint = now;
        }
    };
    RenderSummary s = renderOnCluster(scene, film, opt);
    bar.finish();
    if (s.sppCompleted == 0 && cluster::size() > 1)
        throw Interrupted("render interrupted; under mpirun the image is written only once every band is done, so nothing was written");
    if (s.sppCompleted == 0) throw Error("interrupted before the first pass finished; nothing written");
    fs::path png;
    if (s.cancelled || s.timeBudgetSpent) {
        // Stopped by the time budget, the checkpoint stays too: --resume --time continues the render.
        png = save(film, s.sppCompleted, s.stats, &s);
    } else {
        png = writeOutputs(out, film, scene, s.sppCompleted, &s, a.preview);
        fs::remove(ckptPath, ec);
    }
    s.stats.add(base.stats);
    s.seconds += base.seconds;
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
                                    {"integrator", integratorName(scene.render.integrator)},
                                    {"fluorescence_branches", s.stats.fluorescenceBranches},
                                    {"tentative_collisions", s.stats.tentativeCollisions},
                                    {"scattering_events", s.stats.scatteringEvents},
                                    {"surface_bounces", s.stats.surfaceBounces},
                                    // Null (and branch-process) collisions per real one: the cost of the majorants.
                                    {"null_per_real_collision", nullPerReal(s.stats)},
                                    // Integrator "light": the photons this run traced, and their chains to the camera.
                                    {"photons", s.light.photons},
                                    {"photon_connections", s.light.connections},
                                    // and the camera segments behind glass their vertices were merged with.
                                    {"merged_segments", s.light.mergedSegments},
                                    {"photon_merges", s.light.merges},
                                    {"cancelled", s.cancelled},
                                    {"time_budget_seconds", a.time ? nlohmann::json(*a.time) : nlohmann::json(nullptr)},
                                    {"time_budget_spent", s.timeBudgetSpent}};
    std::printf("%s\n", summary.dump().c_str());
    std::fflush(stdout);
    std::fprintf(stderr, "fluorosim: wrote %s and %s (%d spp in %.1f s)%s\n", out.string().c_str(), png.string().c_str(),
                 s.sppCompleted, s.seconds,
                 s.cancelled         ? " -- interrupted, finished passes kept"
                 : s.timeBudgetSpent ? " -- the --time budget is spent; --resume continues it"
                                     : "");
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
    cmd->add_option("--seed", args->seed, "Random seed (default: the scene's)")->check(nonNegativeInteger());
    cmd->add_option("--fluorescence", args->fluorescence,
                    "Fluorescence model: full (unbiased, default), paper (Abdellah et al.: one event, direct light) or none");
    cmd->add_option("--integrator", args->integrator,
                    "path (the reference: straight shadow rays and phase sampling), mnee (adds manifold next-event estimation "
                    "through glass spheres) or light (mnee, and the fluorescence seen through glass spheres traced from the lights); "
                    "default: the scene's render.integrator");
    cmd->add_option("--checkpoint-seconds", args->checkpointSeconds, "Write the image every this many seconds");
    cmd->add_option("--time", args->time,
                    "Render passes until this many seconds are spent (finished passes only; the same image as a render of the spp it "
                    "reached); without --spp the scene's spp does not stop it");
    cmd->add_flag("--resume", args->resume,
                  "Continue an interrupted render from OUTPUT.checkpoint (same scene, seed and model; --spp may raise the target)");
    cmd->add_option("--preview", args->preview,
                    "What the PNG preview shows: total (default), elastic or fluorescent (the EXR always has all three)")
        ->check(CLI::IsMember({"total", "elastic", "fluorescent"}));
    cmd->callback([args] { runRender(*args); });
}

}  // namespace fluorosim::app
