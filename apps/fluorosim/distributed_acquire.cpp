#include "distributed_acquire.h"

#include <cstring>
#include <map>
#include <mutex>
#include <string_view>
#include <type_traits>

#include "cluster.h"
#include "core/errors.h"

namespace fluorosim::app {
namespace {

// A task is (channel index in the microscope, plane).
uint64_t planeTask(size_t channel, int plane) { return (uint64_t(channel) << 32) | static_cast<uint32_t>(plane); }
size_t taskChannel(uint64_t task) { return static_cast<size_t>(task >> 32); }
int taskPlane(uint64_t task) { return static_cast<int>(task & 0xffffffffu); }

// A plane image as bytes between ranks of the same binary: a fixed header, then the per-pixel arrays
// (electrons and their standard errors) as doubles, so the root stores and summarises exactly what a
// single process would.
struct PlaneHeader {
    int32_t width, height;
    uint8_t complete, pilotsOnLatticeOnly;
    double seconds, largestSample, largestSampleOverPixel;
    double computedElectrons, pathElectrons, pooledElectrons, computedSeconds, pathSeconds;
    uint64_t computedPoints, pathSamples, pilotSamples, nonFiniteSamples;
    PathStats stats;
    optics::UnscatteredTimings computedTimings;
};
static_assert(std::is_trivially_copyable_v<PlaneHeader>);

constexpr size_t kPlaneArrays = 2;
std::vector<double> optics::PlaneImage::*const kArrays[kPlaneArrays] = {&optics::PlaneImage::electrons, &optics::PlaneImage::stderrElectrons};

std::string encodePlane(const optics::PlaneImage& image) {
    const PlaneHeader h{image.width,          image.height,        image.complete,         image.pilotsOnLatticeOnly, image.seconds,
                        image.largestSample,  image.largestSampleOverPixel,               image.computedElectrons,
                        image.pathElectrons,  image.pooledElectrons, image.computedSeconds, image.pathSeconds,   image.computedPoints,
                        image.pathSamples,    image.pilotSamples,  image.nonFiniteSamples, image.stats,       image.computedTimings};
    const size_t pixels = image.electrons.size();
    std::string bytes(sizeof h + kPlaneArrays * pixels * sizeof(double), '\0');
    std::memcpy(bytes.data(), &h, sizeof h);
    for (size_t k = 0; k < kPlaneArrays; ++k) {
        const std::vector<double>& v = image.*kArrays[k];
        if (v.size() == pixels) std::memcpy(bytes.data() + sizeof h + k * pixels * sizeof(double), v.data(), pixels * sizeof(double));
    }
    return bytes;
}

optics::PlaneImage decodePlane(std::string_view bytes) {
    PlaneHeader h;
    if (bytes.size() < sizeof h) throw Error("a plane from another rank is truncated");
    std::memcpy(&h, bytes.data(), sizeof h);
    const size_t pixels = static_cast<size_t>(h.width) * static_cast<size_t>(h.height);
    if (bytes.size() != sizeof h + kPlaneArrays * pixels * sizeof(double)) throw Error("a plane from another rank has the wrong size");
    optics::PlaneImage image;
    image.width = h.width;
    image.height = h.height;
    image.complete = h.complete != 0;
    image.pilotsOnLatticeOnly = h.pilotsOnLatticeOnly != 0;
    image.seconds = h.seconds;
    image.largestSample = h.largestSample;
    image.largestSampleOverPixel = h.largestSampleOverPixel;
    image.computedElectrons = h.computedElectrons;
    image.pathElectrons = h.pathElectrons;
    image.pooledElectrons = h.pooledElectrons;
    image.computedSeconds = h.computedSeconds;
    image.pathSeconds = h.pathSeconds;
    image.computedPoints = h.computedPoints;
    image.pathSamples = h.pathSamples;
    image.pilotSamples = h.pilotSamples;
    image.nonFiniteSamples = h.nonFiniteSamples;
    image.stats = h.stats;
    image.computedTimings = h.computedTimings;
    for (size_t k = 0; k < kPlaneArrays; ++k) {
        std::vector<double>& v = image.*kArrays[k];
        v.resize(pixels);
        std::memcpy(v.data(), bytes.data() + sizeof h + k * pixels * sizeof(double), pixels * sizeof(double));
    }
    return image;
}

// Per-rank options: the node's cores shared among its ranks, and no per-plane progress (planes render
// on several threads at once).
optics::AcquireOptions rankOptions(const optics::AcquireOptions& options, const std::atomic<bool>* cancel) {
    optics::AcquireOptions o = options;
    o.threads = cluster::threadsPerProcess(options.threads);
    o.progress = nullptr;
    o.cancel = cancel;
    return o;
}

// Each rank builds a channel's PSF and computed-part model for its first plane of that channel and
// reuses them for the rest.
class RankImaging {
public:
    const optics::ChannelImaging& at(const Scene& scene, const optics::Microscope& m, size_t channel, const optics::AcquireOptions& o) {
        const std::lock_guard<std::mutex> lock(mutex_);
        auto it = channels_.find(channel);
        if (it == channels_.end()) it = channels_.emplace(channel, optics::setUpChannelImaging(scene, m, channel, o)).first;
        return it->second;
    }

private:
    std::mutex mutex_;
    std::map<size_t, optics::ChannelImaging> channels_;
};

std::string renderTask(const Scene& scene, const optics::Microscope& m, const optics::AcquireOptions& o, RankImaging& imaging, uint64_t task) {
    return encodePlane(optics::acquirePlane(scene, m, taskChannel(task), taskPlane(task), o, &imaging.at(scene, m, taskChannel(task), o)));
}

}  // namespace

bool acquireStackOnCluster(const Scene& scene, const optics::Microscope& m, optics::Stack& stack, const optics::AcquireOptions& options,
                           const optics::StackCallbacks& cb) {
    if (cluster::size() == 1) return optics::acquireStack(scene, m, stack, options, cb);
    std::vector<uint64_t> tasks;  // plane-major, as optics::acquireStack, so an interrupted run holds whole planes
    for (int k = 0; k < stack.planes; ++k)
        for (size_t slot = 0; slot < stack.channels.size(); ++slot)
            if (!stack.done[stack.index(slot, k)]) tasks.push_back(planeTask(stack.channels[slot], k));
    std::atomic<bool> cancelLocal{false};
    const optics::AcquireOptions o = rankOptions(options, &cancelLocal);
    size_t finished = 0;
    for (bool d : stack.done) finished += d;
    cluster::TaskFarm farm;
    RankImaging imaging;
    farm.run = [&](uint64_t task) { return renderTask(scene, m, o, imaging, task); };
    farm.stopRequested = [&] { return options.cancel && options.cancel->load(); };
    farm.cancelLocal = &cancelLocal;
    farm.collect = [&](uint64_t task, const std::string& bytes) {
        const optics::PlaneImage image = decodePlane(bytes);
        if (!image.complete) return;  // cancelled on its rank
        size_t slot = 0;
        while (stack.channels[slot] != taskChannel(task)) ++slot;
        optics::storePlane(stack, m, slot, taskPlane(task), image, options.seed);
        ++finished;
        if (cb.planeDone) cb.planeDone(slot, taskPlane(task), image);
        if (cb.progress) cb.progress(double(finished) / double(stack.done.size()));
    };
    cluster::runTaskFarm(tasks, farm);
    cluster::releaseWorkers();
    return finished == stack.done.size();
}

void servePlanes(const Scene& scene, const optics::Microscope& m, const optics::AcquireOptions& options) {
    const optics::AcquireOptions o = rankOptions(options, options.cancel);
    RankImaging imaging;
    cluster::serveTaskFarms([&](uint64_t task) { return renderTask(scene, m, o, imaging, task); });
}

}  // namespace fluorosim::app
