#include "render/renderer.h"

#include <algorithm>
#include <chrono>
#include <mutex>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/message.h"
#include "core/parallel.h"

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
    const double totalWork = static_cast<double>(options.spp - options.firstSample) * rows;
    double workDone = 0;
    const int perPass = samplesPerPass(options, cam.width, rows);
    requireMemory(static_cast<double>(cam.width) * rows * perPass * sizeof(Film::Row::Sample),
                  "a render pass of " + std::to_string(perPass) + " samples per pixel on " + std::to_string(cam.width) + "x" + std::to_string(rows) +
                      " pixels (its samples are staged until the pass ends)");
    ThreadArena threads(options.threads);
    // Each row of a pass is traced into its staged samples and committed only when every row is done.
    std::vector<Film::Row> staged(static_cast<size_t>(rows));
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
                    film.addSample(r, x, tracer.radiance(ray, cam.medium, wl, rng, stats), wl);
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
        for (int y = 0; y < rows; ++y) film.commit(staged[static_cast<size_t>(y)]);
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
