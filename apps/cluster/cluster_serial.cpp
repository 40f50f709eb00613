// cluster.h without MPI (FLUOROSIM_WITH_MPI=OFF): every run is one process.
#include <cstdlib>

#include "cluster_internal.h"

namespace fluorosim::cluster {

void start(int&, char**&) {}
void finish() {}
int rank() { return 0; }
int size() { return 1; }
void agree(std::exception_ptr failure) {
    if (failure) std::rethrow_exception(failure);
}
bool agreed() { return false; }
bool workersWaiting() { return false; }
void abortRun(int exitCode) { std::exit(exitCode); }
void runTaskFarm(const std::vector<uint64_t>& tasks, const TaskFarm& farm) { detail::runHere(tasks, farm); }
void releaseWorkers() {}
void serveTaskFarms(const std::function<std::string(uint64_t)>&) {}

namespace detail {
int processesOnThisNode() { return 1; }
}  // namespace detail

}  // namespace fluorosim::cluster
