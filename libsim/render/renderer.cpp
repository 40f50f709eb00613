#include "render/renderer.h"

#include <algorithm>
#include <chrono>
#include <mutex>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/parallel.h"

namespace fluorosim {

void RenderOptions::validate() const {
    if (spp <= 0 || spp > (1 << 24)) throw ConfigError("--spp: must lie in [1, 16777216], got " + std::to_string(spp));
    checkThreadCount(threads, "--threads");
    if (sppPerPass <= 0) throw ConfigError("spp per pass must be positive, got " + std::to_string(sppPerPass));
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
    auto cancelled = [&] { return options.cancel && options.cancel->load(std::memory_order_relaxed); };

    for (int passStart = options.firstSample; passStart < options.spp; passStart += options.sppPerPass) {
        if (cancelled()) {
            summary.cancelled = true;
            break;
        }
        const int passEnd = std::min(options.spp, passStart + options.sppPerPass);
        // Each row of the pass is traced into a copy and committed only when every row is done.
        std::vector<Film::Row> staged(static_cast<size_t>(rows));
        std::vector<PathStats> stagedStats(static_cast<size_t>(rows));
        std::vector<char> done(static_cast<size_t>(rows), 0);
        parallelFor(static_cast<size_t>(rows), options.threads, [&](size_t row) {
            if (cancelled()) return;
            const int y = options.firstRow + static_cast<int>(row);
            Film::Row r = film.row(static_cast<int>(row));
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
            staged[row] = std::move(r);
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
    }
    for (const PathStats& s : rowStats) summary.stats.add(s);
    summary.nonFiniteSamples = film.nonFiniteSamples();
    summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return summary;
}

}  // namespace fluorosim
