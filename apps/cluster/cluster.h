#pragma once
// The processes of one run: `mpirun -np N fluorosim ...` runs N ranks. This module is the only place
// that includes MPI (cluster_mpi.cpp); built without MPI (FLUOROSIM_WITH_MPI=OFF) or started without
// an MPI launcher, a run is one process and MPI is never initialised, so normal runs and tests need
// no launcher.
//
// Work is shared by a task farm: the root (rank 0) hands out task numbers one at a time to whichever
// process asks next, its own worker thread included, and collects each result as bytes. Tasks of
// unequal cost (planes with more or less tissue in the sheet) therefore balance themselves. Results
// must not depend on which process computes them (the random streams are keyed by the task's
// content), so the output is the same for any number of processes. Only the root collects, writes
// files and checkpoints.
//
// A command may run several farms one after another (a fit distributes the renders of each objective
// evaluation): the root calls runTaskFarm as often as it needs and then releaseWorkers; the other
// ranks call serveTaskFarms once, which serves every farm until the release.
//
// Failures. Before its first farm every rank passes agree(): if any rank failed while setting up (bad
// input, a file missing on one node), every rank throws the failure of the lowest failing rank, with
// its type and message ("rank 2 of 4: ..." when it was not the root), and main prints it once, on the
// root. A worker's exception during a farm is rethrown on the root the same way; main then prints it
// and ends the whole run (abortRun). A rank killed outright is mpirun's to report: it names the rank
// and sends SIGTERM to the others, upon which the root stops its farm without waiting for the dead
// rank, and the command ends the run as it ends an interrupted one (acquire writes its complete planes
// and keeps every collected plane in its checkpoint for --resume).
#include <atomic>
#include <cstdint>
#include <exception>
#include <functional>
#include <string>
#include <vector>

namespace fluorosim::cluster {

// Joins the MPI job when an MPI launcher (mpirun or mpiexec of OpenMPI or MPICH, srun with PMI or
// PMIx) started this process, as its environment shows; otherwise does nothing. Call at the start of
// main; finish() before returning from it.
void start(int& argc, char**& argv);
void finish();

int rank();  // 0 when alone
int size();  // 1 when alone
inline bool isRoot() { return rank() == 0; }
// Threads for one process: `requested` when positive; otherwise the cores of this node shared among
// the ranks on it (all cores when alone).
int threadsPerProcess(int requested);

// Collective, once per command before its first farm (runTaskFarm and serveTaskFarms call it when no
// one has). Each rank passes the exception its setup threw, or none. If any rank failed, every rank
// throws the lowest failing rank's error (ConfigError, IoError, NumericError, Error or
// std::runtime_error for anything else, keeping the message).
void agree(std::exception_ptr failure = nullptr);
bool agreed();
// True on the root between agree() and releaseWorkers(): other ranks are waiting for work, so a
// failure must end the whole run (abortRun), not just this process.
bool workersWaiting();
// Ends every process of the run with this exit code (MPI_Abort), or this one when alone.
[[noreturn]] void abortRun(int exitCode);

struct TaskFarm {
    // Computes one task; on any rank, and on the root from a second thread while the calling thread
    // collects. Its exceptions reach the root's runTaskFarm.
    std::function<std::string(uint64_t task)> run;
    // Root only, on the thread that called runTaskFarm, once per task handed out, in arrival order.
    std::function<void(uint64_t task, const std::string& result)> collect;
    // Root only: once true, no further task is handed out (the ones out are still collected).
    std::function<bool()> stopRequested;
    // Root only: set by the farm when it stops early (stopRequested, or a failure anywhere), so that
    // the root's own task in progress ends soon; `run` should watch it. May be null.
    std::atomic<bool>* cancelLocal = nullptr;
};

// Root: runs `tasks` (handed out in this order) and returns once every task handed out is collected,
// or, once stopped early, as soon as the root's own task has ended: tasks still out on other ranks are
// then abandoned, no farm may follow, releaseWorkers does nothing and workersWaiting stays true, so
// the run must end through abortRun. Alone, runs them in order on the calling thread.
void runTaskFarm(const std::vector<uint64_t>& tasks, const TaskFarm& farm);
// Root: tells the other ranks that no farm follows. Safe to call when alone or more than once.
void releaseWorkers();
// Other ranks: compute the tasks the root hands out, farm after farm, until it releases them.
void serveTaskFarms(const std::function<std::string(uint64_t task)>& run);

}  // namespace fluorosim::cluster
