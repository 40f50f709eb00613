#pragma once
// Parallel loops over independent work items. Callers make results independent of scheduling by
// keying random streams on the item index and reducing per-item results in index order.
#include <cstddef>
#include <functional>

namespace fluorosim {

// Runs body(i) for i in [0, count) on `threads` threads (0 = all cores).
void parallelFor(size_t count, int threads, const std::function<void(size_t)>& body);

int defaultThreadCount();

}  // namespace fluorosim
