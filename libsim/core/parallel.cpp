#include "core/parallel.h"

#include <tbb/blocked_range.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <string>

#include "core/errors.h"

namespace fluorosim {

int defaultThreadCount() { return tbb::info::default_concurrency(); }

void checkThreadCount(int threads, std::string_view option) {
    if (threads < 0 || threads > kMaxThreads)
        throw ConfigError(std::string(option) + ": must lie in [0, " + std::to_string(kMaxThreads) + "] (0 = all cores), got " +
                          std::to_string(threads));
}

namespace {

void loop(size_t count, const std::function<void(size_t)>& body) {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 1), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) body(i);
    });
}

int threadsFor(int threads) {
    checkThreadCount(threads, "threads");
    return threads <= 0 ? defaultThreadCount() : threads;
}

}  // namespace

void parallelFor(size_t count, int threads, const std::function<void(size_t)>& body) {
    ThreadArena(threads).parallelFor(count, body);
}

struct ThreadArena::Impl {
    int threads;
    tbb::task_arena arena;
    explicit Impl(int n) : threads(n), arena(n) {}
};

ThreadArena::ThreadArena(int threads) : impl_(std::make_unique<Impl>(threadsFor(threads))) {}

ThreadArena::~ThreadArena() = default;

void ThreadArena::parallelFor(size_t count, const std::function<void(size_t)>& body) {
    if (impl_->threads == 1) {
        for (size_t i = 0; i < count; ++i) body(i);
        return;
    }
    impl_->arena.execute([&] { loop(count, body); });
}

}  // namespace fluorosim
