#include "render/renderer.h"

#include <algorithm>
#include <chrono>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/message.h"
#include "core/parallel.h"
#include "render/photon_merging.h"

namespace fluorosim {

void RenderOptions::validate() const {
    if (spp <= 0 || spp > (1 << 24)) throw ConfigError("--spp: must lie in [1, 16777216], got " + std::to_string(spp));
    checkThreadCount(threads, "--threads");
    if (!(timeBudgetSeconds >= 0) || timeBudgetSeconds > 1e9)
        throw ConfigError("--time: must be 0 (no budget) or lie in (0, 1e9] seconds, got " + messageNumber(timeBudgetSeconds));
    if (sppPerPass < 0) throw ConfigError("spp per pass must be 0 (automatic) or positive, got " + std::to_string(sppPerPass));
    if (firstSample < 0 || firstSample > spp)
        throw ConfigError("--spp: must be at least the " + std::to_string(firstSample) + " samples per pixel already rendered, got " +
                          std::to_string(spp));
}

Ray cameraRay(const Camera& camera, int x, int y, double u1, double u2) {
    const double aspect = static_cast<double>(camera.width) / camera.height;
    const double sx = (2.0 * (x + u1) / camera.width - 1.0) * camera.tanHalfFovY * aspect;
    const double sy = (1.0 - 2.0 * (y + u2) / camera.height) * camera.tanHalfFovY;
    return Ray{camera.position, normalize(camera.frame.n + camera.frame.s * sx + camera.frame.t * sy)};
}

int samplesPerPass(const RenderOptions& options, int width, int rows) {
    if (options.sppPerPass > 0) return options.sppPerPass;
    const double pixels = static_cast<double>(width) * rows;
    return static_cast<int>(std::clamp(std::ceil(kMinPathsPerPass / pixels), 1.0, static_cast<double>(options.spp)));
}

RenderSummary render(const Scene& scene, Film& film, const RenderOptions& options) {
    options.validate();
    const auto start = std::chrono::steady_clock::now();
    const PathTracer tracer(scene);
    // Integrator::Light: each pass also traces photons (LightTracer::photonsPerSample per sample),
    // whose splats land anywhere in the image, so the film must hold all of it.
    std::optional<LightTracer> lightTracer;
    if (scene.render.integrator == Integrator::Light) {
        if (options.firstRow != 0 || film.height() != scene.camera.height)
            throw ConfigError("the light integrator renders whole images, not bands of rows (distributed renders): use \"mnee\" there");
        lightTracer.emplace(scene, tracer);
    }
    const WavelengthSampler wavelengths = cameraWavelengthSampler(scene, tracer.fluorescence().active());

    const Camera& cam = scene.camera;
    const int rows = film.height();
    if (film.width() != cam.width || options.firstRow < 0 || options.firstRow + rows > cam.height)
        throw Error("a film of " + std::to_string(film.width()) + "x" + std::to_string(rows) + " from row " + std::to_string(options.firstRow) +
                    " does not fit the camera's " + std::to_string(cam.width) + "x" + std::to_string(cam.height) + " image");
    RenderSummary summary;
    summary.sppCompleted = options.firstSample;
    std::vector<PathStats> rowStats(static_cast<size_t>(rows));
    std::mutex progressMutex;
    // Progress counts rows of passes; with photons, a pass's photon batches count as much as its rows.
    const double totalWork = static_cast<double>(options.spp - options.firstSample) * rows * (lightTracer ? 2 : 1);
    double workDone = 0;
    const int perPass = samplesPerPass(options, cam.width, rows);
    requireMemory(static_cast<double>(cam.width) * rows * perPass * sizeof(Film::Row::Sample),
                  "a render pass of " + std::to_string(perPass) + " samples per pixel on " + std::to_string(cam.width) + "x" + std::to_string(rows) +
                      " pixels (its samples are staged until the pass ends)");
    ThreadArena threads(options.threads);
    // Each row of a pass is traced into its staged samples and committed only when every row is done.
    std::vector<Film::Row> staged(static_cast<size_t>(rows));
    PathStart pathStart;
    pathStart.lightTracedFluorescence = lightTracer.has_value();
    pathStart.mergedSegments = lightTracer.has_value() && scene.render.mergeRadiusPixels > 0;
    auto cancelled = [&] { return options.cancel && options.cancel->load(std::memory_order_relaxed); };

    for (int passStart = options.firstSample; passStart < options.spp; passStart += perPass) {
        if (cancelled()) {
            summary.cancelled = true;
            break;
        }
        const int passEnd = std::min(options.spp, passStart + perPass);
        std::vector<PathStats> stagedStats(static_cast<size_t>(rows));
        std::vector<char> done(static_cast<size_t>(rows), 0);
        threads.parallelFor(static_cast<size_t>(rows), [&](size_t row) {
            if (cancelled()) return;
            const int y = options.firstRow + static_cast<int>(row);
            Film::Row& r = staged[row];
            r.reset(static_cast<int>(row));
            PathStats stats = rowStats[row];
            for (int x = 0; x < cam.width; ++x) {
                if (cancelled()) return;
                const uint64_t pixel = static_cast<uint64_t>(y) * static_cast<uint64_t>(cam.width) + static_cast<uint64_t>(x);
                for (int s = passStart; s < passEnd; ++s) {
                    Rng rng = Rng::forKey(options.seed, pixel, static_cast<uint64_t>(s));
                    const SampledWavelengths wl = wavelengths.sample(rng.uniform(), rng.uniform());
                    const Ray ray = cameraRay(cam, x, y, rng.uniform(), rng.uniform());
                    film.addSample(r, x, tracer.radiance(ray, cam.medium, wl, rng, stats, pathStart), wl);
                }
            }
            stagedStats[row] = stats;
            done[row] = 1;
            if (options.progress) {
                std::lock_guard<std::mutex> lock(progressMutex);
                workDone += passEnd - passStart;
                options.progress(workDone / totalWork);
            }
        });
        if (std::find(done.begin(), done.end(), 0) != done.end()) {
            summary.cancelled = true;  // the pass was abandoned: the film keeps the passes before it
            break;
        }
        // The pass's photons, in batches of fixed photon indices whose splats are committed in order, so the
        // image does not depend on the thread count either.
        std::vector<std::vector<FilmSplat>> splats;
        std::vector<LightTraceStats> batchStats;
        if (lightTracer) {
            // The camera rays' chains into media behind glass, which the photons merge with.
            std::optional<CameraSegments> merging;
            if (pathStart.mergedSegments) merging.emplace(scene, tracer, options.seed, passStart, passEnd, threads);
            const CameraSegments* segments = merging && merging->size() > 0 ? &*merging : nullptr;
            constexpr uint64_t kBatch = 4096;
            const double perSample = lightTracer->photonsPerSample();
            const auto first = static_cast<uint64_t>(passStart * perSample), end = static_cast<uint64_t>(passEnd * perSample);
            const size_t batches = static_cast<size_t>((end - first + kBatch - 1) / kBatch);
            splats.resize(batches);
            batchStats.resize(batches);
            std::vector<char> batchDone(batches, 0);
            threads.parallelFor(batches, [&](size_t b) {
                const uint64_t from = first + b * kBatch, to = std::min(end, from + kBatch);
                for (uint64_t i = from; i < to; ++i) {
                    if ((i & 63) == 0 && cancelled()) return;
                    lightTracer->trace(options.seed, i, splats[b], batchStats[b], segments);
                }
                // A pass holds every batch's splats until it commits them: bounded by the memory cap, judged
                // from this batch.
                requireMemory(static_cast<double>(splats[b].capacity()) * sizeof(FilmSplat) * static_cast<double>(batches),
                              "the light tracer's splats of a pass of " + std::to_string(end - first) + " photons");
                batchDone[b] = 1;
                if (options.progress) {
                    std::lock_guard<std::mutex> lock(progressMutex);
                    workDone += static_cast<double>(passEnd - passStart) * rows / static_cast<double>(batches);
                    options.progress(std::min(1.0, workDone / totalWork));
                }
            });
            if (std::find(batchDone.begin(), batchDone.end(), 0) != batchDone.end()) {
                summary.cancelled = true;
                break;
            }
            if (segments) summary.light.mergedSegments += segments->size();
        }
        for (int y = 0; y < rows; ++y) film.commit(staged[static_cast<size_t>(y)]);
        for (size_t b = 0; b < splats.size(); ++b) {
            for (const FilmSplat& s : splats[b]) film.addSplat(s.x, s.y, s.lambda, s.value, s.fluorescent);
            summary.light.add(batchStats[b]);
        }
        rowStats = std::move(stagedStats);
        summary.sppCompleted = passEnd;
        if (options.passFinished) {
            PathStats stats;
            for (const PathStats& st : rowStats) stats.add(st);
            options.passFinished(film, passEnd, stats);
        }
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        if (options.timeBudgetSeconds > 0 && passEnd < options.spp && elapsed >= options.timeBudgetSeconds) {
            summary.timeBudgetSpent = true;
            break;
        }
    }
    for (const PathStats& s : rowStats) summary.stats.add(s);
    summary.nonFiniteSamples = film.nonFiniteSamples();
    summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return summary;
}

}  // namespace fluorosim
