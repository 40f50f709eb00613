#pragma once
// Parallel loops over independent work items. Callers make results independent of scheduling by
// keying random streams on the item index and reducing per-item results in index order.
#include <cstddef>
#include <functional>
#include <memory>
#include <string_view>

namespace fluorosim {

// Thread counts are 0 (all cores) to kMaxThreads; TBB crashes on absurd arena sizes (65537).
inline constexpr int kMaxThreads = 4096;
// Throws ConfigError "<option>: must lie in [0, 4096] (0 = all cores), got N" outside that range.
void checkThreadCount(int threads, std::string_view option);

// Runs body(i) for i in [0, count) on `threads` threads (0 = all cores); checks `threads` first.
void parallelFor(size_t count, int threads, const std::function<void(size_t)>& body);

int defaultThreadCount();

// The threads of many successive parallel loops (the passes of a render): made once, so a loop of
// small items does not pay for starting and stopping its workers each time.
class ThreadArena {
public:
    explicit ThreadArena(int threads);  // 0 = all cores; checks `threads` as parallelFor does
    ~ThreadArena();
    ThreadArena(const ThreadArena&) = delete;
    ThreadArena& operator=(const ThreadArena&) = delete;
    // Runs body(i) for i in [0, count) on the arena's threads.
    void parallelFor(size_t count, const std::function<void(size_t)>& body);

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace fluorosim
