#pragma once
// Shared by the MPI and the single-process implementations of cluster.h.
#include <cstdint>
#include <vector>

#include "cluster.h"

namespace fluorosim::cluster::detail {

// Ranks of the run on this node (1 when alone).
int processesOnThisNode();
// A farm on one process: the tasks in order on the calling thread, until stopRequested.
void runHere(const std::vector<uint64_t>& tasks, const TaskFarm& farm);

}  // namespace fluorosim::cluster::detail
