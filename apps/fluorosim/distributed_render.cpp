#include "distributed_render.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <string_view>
#include <type_traits>

#include "cluster.h"
#include "core/errors.h"

namespace fluorosim::app {
namespace {

// Rows per band: about 16 bands per rank, so that faster ranks take more of them.
int bandRows(int height) { return std::max(1, height / (16 * cluster::size())); }

struct BandHeader {
    int32_t sppCompleted;
    uint8_t cancelled;
    PathStats stats;
};
static_assert(std::is_trivially_copyable_v<BandHeader>);

std::string renderBand(const Scene& scene, const Film& film, const RenderOptions& options, uint64_t task) {
    const int rows = bandRows(film.height()), first = static_cast<int>(task) * rows;
    Film band = film.band(std::min(rows, film.height() - first));
    RenderOptions o = options;
    o.firstRow = first;
    o.threads = cluster::threadsPerProcess(options.threads);
    o.progress = nullptr;
    o.passFinished = nullptr;
    const RenderSummary s = render(scene, band, o);
    const BandHeader h{s.sppCompleted, s.cancelled, s.stats};
    return std::string(reinterpret_cast<const char*>(&h), sizeof h) + band.sums();
}

}  // namespace

RenderSummary renderOnCluster(const Scene& scene, Film& film, const RenderOptions& options) {
    if (cluster::size() == 1) return render(scene, film, options);
    options.validate();
    const auto start = std::chrono::steady_clock::now();
    const int rows = bandRows(film.height()), bands = (film.height() + rows - 1) / rows;
    std::vector<uint64_t> tasks;
    for (int b = 0; b < bands; ++b) tasks.push_back(static_cast<uint64_t>(b));
    std::atomic<bool> cancelLocal{false};
    RenderOptions local = options;
    local.cancel = &cancelLocal;
    RenderSummary summary;
    int complete = 0;
    cluster::TaskFarm farm;
    farm.run = [&](uint64_t task) { return renderBand(scene, film, local, task); };
    farm.stopRequested = [&] { return options.cancel && options.cancel->load(); };
    farm.cancelLocal = &cancelLocal;
    farm.collect = [&](uint64_t task, const std::string& bytes) {
        BandHeader h;
        if (bytes.size() < sizeof h) throw Error("a band from another rank is truncated");
        std::memcpy(&h, bytes.data(), sizeof h);
        if (h.cancelled || h.sppCompleted != options.spp) return;
        const int first = static_cast<int>(task) * rows;
        Film band = film.band(std::min(rows, film.height() - first));
        band.setSums(std::string_view(bytes).substr(sizeof h));
        film.placeRows(first, band);
        summary.stats.add(h.stats);
        ++complete;
        if (options.progress) options.progress(double(complete) / double(bands));
    };
    cluster::runTaskFarm(tasks, farm);
    cluster::releaseWorkers();
    summary.cancelled = complete < bands;
    summary.sppCompleted = summary.cancelled ? 0 : options.spp;
    summary.nonFiniteSamples = film.nonFiniteSamples();
    summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return summary;
}

void serveBands(const Scene& scene, const Film& film, const RenderOptions& options) {
    cluster::serveTaskFarms([&](uint64_t task) { return renderBand(scene, film, options, task); });
}

}  // namespace fluorosim::app
