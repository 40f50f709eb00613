// The parts of cluster.h that do not depend on MPI.
#include <algorithm>

#include "cluster_internal.h"
#include "core/parallel.h"

namespace fluorosim::cluster {

int threadsPerProcess(int requested) {
    if (requested > 0) return requested;
    return std::max(1, defaultThreadCount() / std::max(1, detail::processesOnThisNode()));
}

namespace detail {

void runHere(const std::vector<uint64_t>& tasks, const TaskFarm& farm) {
    for (uint64_t task : tasks) {
        if (farm.stopRequested && farm.stopRequested()) return;
        farm.collect(task, farm.run(task));
    }
}

}  // namespace detail
}  // namespace fluorosim::cluster
