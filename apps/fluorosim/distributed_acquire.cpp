#include "distributed_acquire.h"

#include <cstring>
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

// A plane image as bytes between ranks of the same binary: a fixed header, then electrons and their
// standard errors as doubles, so the root stores exactly what a single process would.
struct PlaneHeader {
    int32_t width, height;
    uint8_t complete;
    double seconds, largestSample;
    PathStats stats;
};
static_assert(std::is_trivially_copyable_v<PlaneHeader>);

std::string encodePlane(const optics::PlaneImage& image) {
    const PlaneHeader h{image.width, image.height, image.complete, image.seconds, image.largestSample, image.stats};
    const size_t n = image.electrons.size() * sizeof(double);
    std::string bytes(sizeof h + 2 * n, '\0');
    std::memcpy(bytes.data(), &h, sizeof h);
    std::memcpy(bytes.data() + sizeof h, image.electrons.data(), n);
    std::memcpy(bytes.data() + sizeof h + n, image.stderrElectrons.data(), n);
    return bytes;
}

optics::PlaneImage decodePlane(std::string_view bytes) {
    PlaneHeader h;
    if (bytes.size() < sizeof h) throw Error("a plane from another rank is truncated");
    std::memcpy(&h, bytes.data(), sizeof h);
    const size_t pixels = static_cast<size_t>(h.width) * static_cast<size_t>(h.height);
    if (bytes.size() != sizeof h + 2 * pixels * sizeof(double)) throw Error("a plane from another rank has the wrong size");
    optics::PlaneImage image;
    image.width = h.width;
    image.height = h.height;
    image.complete = h.complete != 0;
    image.seconds = h.seconds;
    image.largestSample = h.largestSample;
    image.stats = h.stats;
    image.electrons.resize(pixels);
    image.stderrElectrons.resize(pixels);
    std::memcpy(image.electrons.data(), bytes.data() + sizeof h, pixels * sizeof(double));
    std::memcpy(image.stderrElectrons.data(), bytes.data() + sizeof h + pixels * sizeof(double), pixels * sizeof(double));
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

std::string renderTask(const Scene& scene, const optics::Microscope& m, const optics::AcquireOptions& o, uint64_t task) {
    return encodePlane(optics::acquirePlane(scene, m, taskChannel(task), taskPlane(task), o));
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
    farm.run = [&](uint64_t task) { return renderTask(scene, m, o, task); };
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
    cluster::serveTaskFarms([&](uint64_t task) { return renderTask(scene, m, o, task); });
}

}  // namespace fluorosim::app
