// cluster.h over MPI (OpenMPI or MPICH, C API). Only the calling thread of the root and the main
// thread of the other ranks call MPI (MPI_THREAD_FUNNELED); the root's own worker is a second thread
// that never does. Waits poll with 1 ms sleeps: a blocking receive in OpenMPI spins a core, which
// would take it from the renderer.
//
// Messages (MPI_COMM_WORLD, tags below): a worker sends kReady once, then kResult (8-byte task number
// and the result's bytes) or kFailed (1-byte kind and the message) for each task; the root answers
// kTask (8-byte task number) or, after the last farm, kEnd. A worker that asks when the current farm
// has nothing left waits ("parked") until the next farm or the release.
#include <mpi.h>

#include <chrono>
#include <climits>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <utility>

#include "cluster_internal.h"
#include "core/errors.h"

namespace fluorosim::cluster {
namespace {

enum Tag : int { kReady = 1, kResult = 2, kFailed = 3, kTask = 4, kEnd = 5 };
enum class Kind : char { Config = 'C', Io = 'I', Numeric = 'N', Other = 'E', Internal = 'X' };

bool gStarted = false, gAgreed = false, gWorkersWaiting = false;
bool gAbandoned = false;  // root: a farm stopped with tasks still out on other ranks
int gRank = 0, gSize = 1, gOnNode = 1;
std::vector<int> gParked;  // root: workers waiting for a task
int gCheckedIn = 0;        // root: workers that have sent kReady

bool launchedByMpi() {
    for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "MPI_LOCALNRANKS"})
        if (std::getenv(v)) return true;
    return false;
}

void pause() { std::this_thread::sleep_for(std::chrono::milliseconds(1)); }

void waitFor(MPI_Request& request) {
    int done = 0;
    while (MPI_Test(&request, &done, MPI_STATUS_IGNORE) == MPI_SUCCESS && !done) pause();
}

void sendBytes(const std::string& bytes, int to, int tag) {
    if (bytes.size() > static_cast<size_t>(INT_MAX))
        throw Error("a result of " + std::to_string(bytes.size()) + " bytes is too large for one MPI message");
    MPI_Request request;
    MPI_Isend(bytes.data(), static_cast<int>(bytes.size()), MPI_BYTE, to, tag, MPI_COMM_WORLD, &request);
    waitFor(request);
}

std::string receiveBytes(const MPI_Status& probed) {
    int count = 0;
    MPI_Get_count(&probed, MPI_BYTE, &count);
    std::string bytes(static_cast<size_t>(count), '\0');
    MPI_Recv(bytes.data(), count, MPI_BYTE, probed.MPI_SOURCE, probed.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    return bytes;
}

std::optional<MPI_Status> probe(int from) {
    int flag = 0;
    MPI_Status status;
    MPI_Iprobe(from, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &status);
    if (!flag) return std::nullopt;
    return status;
}

std::string taskBytes(uint64_t task) { return std::string(reinterpret_cast<const char*>(&task), sizeof task); }
uint64_t readTask(const std::string& bytes) {
    uint64_t task = 0;
    std::memcpy(&task, bytes.data(), sizeof task);
    return task;
}

std::string encodeFailure(std::exception_ptr failure) {
    try {
        std::rethrow_exception(failure);
    } catch (const ConfigError& e) {
        return char(Kind::Config) + std::string(e.what());
    } catch (const IoError& e) {
        return char(Kind::Io) + std::string(e.what());
    } catch (const NumericError& e) {
        return char(Kind::Numeric) + std::string(e.what());
    } catch (const Error& e) {
        return char(Kind::Other) + std::string(e.what());
    } catch (const std::exception& e) {
        return char(Kind::Internal) + std::string(e.what());
    } catch (...) {
        return char(Kind::Internal) + std::string("unknown exception");
    }
}

[[noreturn]] void throwFailure(const std::string& encoded, int fromRank) {
    const std::string where = fromRank == 0 ? "" : "rank " + std::to_string(fromRank) + " of " + std::to_string(gSize) + ": ";
    const std::string message = where + encoded.substr(1);
    switch (static_cast<Kind>(encoded.empty() ? 'X' : encoded[0])) {
        case Kind::Config: throw ConfigError(message);
        case Kind::Io: throw IoError(message);
        case Kind::Numeric: throw NumericError(message);
        case Kind::Other: throw Error(message);
        default: throw std::runtime_error(message);
    }
}

// Root: waits for one message from a worker that has not checked in yet or asks again, parking it.
void parkNextWorker() {
    while (true) {
        if (const auto st = probe(MPI_ANY_SOURCE)) {
            const std::string bytes = receiveBytes(*st);
            if (st->MPI_TAG == kFailed) throwFailure(bytes, st->MPI_SOURCE);
            if (st->MPI_TAG == kReady) ++gCheckedIn;
            gParked.push_back(st->MPI_SOURCE);
            return;
        }
        pause();
    }
}

}  // namespace

void start(int& argc, char**& argv) {
    if (gStarted || !launchedByMpi()) return;
    int provided = 0;
    MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
    gStarted = true;
    MPI_Comm_rank(MPI_COMM_WORLD, &gRank);
    MPI_Comm_size(MPI_COMM_WORLD, &gSize);
    MPI_Comm node;
    MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node);
    MPI_Comm_size(node, &gOnNode);
    MPI_Comm_free(&node);
}

void finish() {
    if (!gStarted) return;
    MPI_Finalize();
    gStarted = false;
}

int rank() { return gRank; }
int size() { return gSize; }
bool agreed() { return gAgreed; }
bool workersWaiting() { return gWorkersWaiting; }

void abortRun(int exitCode) {
    if (gStarted && gSize > 1) MPI_Abort(MPI_COMM_WORLD, exitCode);
    std::exit(exitCode);
}

void agree(std::exception_ptr failure) {
    if (gSize == 1 || gAgreed) {
        if (failure) std::rethrow_exception(failure);
        return;
    }
    gAgreed = true;
    const int mine = failure ? gRank : gSize;
    int lowest = gSize;
    MPI_Allreduce(&mine, &lowest, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    if (lowest == gSize) {
        gWorkersWaiting = gRank == 0;
        return;
    }
    std::string encoded = lowest == gRank ? encodeFailure(failure) : std::string();
    int length = static_cast<int>(encoded.size());
    MPI_Bcast(&length, 1, MPI_INT, lowest, MPI_COMM_WORLD);
    encoded.resize(static_cast<size_t>(length));
    MPI_Bcast(encoded.data(), length, MPI_BYTE, lowest, MPI_COMM_WORLD);
    throwFailure(encoded, lowest);
}

namespace {

// The root's own worker: takes tasks from the shared list on a second thread (it never calls MPI).
struct LocalWorker {
    struct Outcome {
        uint64_t task;
        std::string result;
        std::exception_ptr error;
    };
    std::mutex mutex;
    const std::vector<uint64_t>& tasks;
    size_t next = 0, handedOut = 0;
    bool stopped = false, finished = false;
    std::deque<Outcome> outcomes;

    explicit LocalWorker(const std::vector<uint64_t>& t) : tasks(t) {}
    std::optional<uint64_t> take() {
        const std::lock_guard<std::mutex> lock(mutex);
        if (stopped || next == tasks.size()) return std::nullopt;
        ++handedOut;
        return tasks[next++];
    }
    void work(const TaskFarm& farm) {
        while (const auto task = take()) {
            Outcome o{*task, {}, nullptr};
            try {
                o.result = farm.run(*task);
            } catch (...) {
                o.error = std::current_exception();
            }
            const std::lock_guard<std::mutex> lock(mutex);
            const bool failed = o.error != nullptr;
            outcomes.push_back(std::move(o));
            if (failed) break;
        }
        const std::lock_guard<std::mutex> lock(mutex);
        finished = true;
    }
};

}  // namespace

void runTaskFarm(const std::vector<uint64_t>& tasks, const TaskFarm& farm) {
    if (gSize == 1) return detail::runHere(tasks, farm);
    if (gAbandoned) throw Error("internal: a task farm after one that stopped early (the run can only be ended)");
    if (!gAgreed) agree();
    LocalWorker local(tasks);
    size_t collected = 0;
    bool stopped = false;
    const auto stopEarly = [&] {
        stopped = true;
        {
            const std::lock_guard<std::mutex> lock(local.mutex);
            local.stopped = true;
        }
        if (farm.cancelLocal) farm.cancelLocal->store(true);
    };
    // A thread rather than parallelFor: it runs beside this one for the whole farm, not as a loop.
    std::thread thread([&] { local.work(farm); });
    const auto fail = [&](auto&& rethrow) {
        stopEarly();
        thread.join();  // its task was cancelled through cancelLocal, so this is short
        rethrow();
    };
    const auto give = [&](int worker) {
        if (const auto task = local.take()) sendBytes(taskBytes(*task), worker, kTask);
        else gParked.push_back(worker);
    };
    for (const int worker : std::exchange(gParked, {})) give(worker);
    try {
        while (true) {
            if (farm.stopRequested && farm.stopRequested()) stopEarly();
            std::deque<LocalWorker::Outcome> ready;
            {
                const std::lock_guard<std::mutex> lock(local.mutex);
                ready.swap(local.outcomes);
            }
            for (auto& o : ready) {
                if (o.error) fail([&] { std::rethrow_exception(o.error); });
                ++collected;
                farm.collect(o.task, o.result);
            }
            if (const auto st = probe(MPI_ANY_SOURCE)) {
                std::string bytes = receiveBytes(*st);
                if (st->MPI_TAG == kFailed) fail([&] { throwFailure(bytes, st->MPI_SOURCE); });
                if (st->MPI_TAG == kReady) ++gCheckedIn;
                give(st->MPI_SOURCE);  // before collecting, so the worker is not idle meanwhile
                if (st->MPI_TAG == kResult) {
                    ++collected;
                    farm.collect(readTask(bytes), bytes.substr(sizeof(uint64_t)));
                }
                continue;
            }
            {
                const std::lock_guard<std::mutex> lock(local.mutex);
                if (local.finished && collected == local.handedOut) break;
                // Stopped: the tasks still out on other ranks are not awaited. A signal reaches every
                // rank, so they are cancelled anyway; and when a rank has died (mpirun then signals the
                // others), its task would never come back.
                if (local.finished && stopped && local.outcomes.empty()) {
                    gAbandoned = true;
                    break;
                }
            }
            pause();
        }
    } catch (...) {
        if (thread.joinable()) {
            stopEarly();
            thread.join();
        }
        throw;
    }
    thread.join();
}

void releaseWorkers() {
    if (gSize == 1 || gRank != 0 || !gWorkersWaiting || gAbandoned) return;
    while (gCheckedIn < gSize - 1 || static_cast<int>(gParked.size()) < gSize - 1) parkNextWorker();
    for (const int worker : std::exchange(gParked, {})) sendBytes(std::string(), worker, kEnd);
    gWorkersWaiting = false;
}

void serveTaskFarms(const std::function<std::string(uint64_t)>& run) {
    if (gSize == 1 || gRank == 0) return;
    if (!gAgreed) agree();
    sendBytes(std::string(), 0, kReady);
    while (true) {
        std::optional<MPI_Status> st;
        while (!(st = probe(0))) pause();
        const std::string bytes = receiveBytes(*st);
        if (st->MPI_TAG == kEnd) return;
        const uint64_t task = readTask(bytes);
        std::string reply;
        int tag = kResult;
        try {
            reply = taskBytes(task) + run(task);
        } catch (...) {
            reply = encodeFailure(std::current_exception());
            tag = kFailed;
        }
        sendBytes(reply, 0, tag);
    }
}

namespace detail {
int processesOnThisNode() { return gOnNode; }
}  // namespace detail

}  // namespace fluorosim::cluster
