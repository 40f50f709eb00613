// fluorosim: command-line front end. Library errors arrive as typed exceptions and become a
// one-line message and a non-zero exit code here. Under mpirun every rank runs this; only the root
// prints errors (cluster/cluster.h).
#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <new>
#include <string>

#include "cluster.h"
#include "commands.h"
#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/message.h"

namespace {

#if defined(__SANITIZE_ADDRESS__)
constexpr bool kSanitized = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(memory_sanitizer) || __has_feature(thread_sanitizer)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif
#else
constexpr bool kSanitized = false;
#endif

// Room beyond the cap for what no estimate covers: code, libraries, the spectral database, thread
// stacks and allocator slack.
constexpr uint64_t kUnestimatedBytes = uint64_t(2) << 30;

// Sets the memory cap from --memory-cap, else FLUOROSIM_MEMORY_CAP, else the default, and makes it a
// hard limit on the heap (RLIMIT_DATA), so that an allocation no estimate foresaw (a corrupt file deep
// inside a third-party reader) fails with bad_alloc instead of exhausting the machine. Sanitizer builds
// reserve terabytes of shadow memory and are left without the limit.
void applyMemoryCap(const std::string& option) {
    using fluorosim::ConfigError;
    std::string text = option, source = "--memory-cap";
    if (text.empty()) {
        if (const char* env = std::getenv("FLUOROSIM_MEMORY_CAP")) text = env, source = "FLUOROSIM_MEMORY_CAP";
    }
    if (!text.empty()) {
        const auto bytes = fluorosim::parseByteSize(text);
        if (!bytes)
            throw ConfigError(source + ": expected a size such as 8GiB, 512MiB or 2G, got \"" + fluorosim::excerpt(text) + "\"");
        fluorosim::setMemoryCapBytes(*bytes);
    }
    if (kSanitized) return;
    rlimit limit{};
    if (::getrlimit(RLIMIT_DATA, &limit) != 0) return;
    const rlim_t want = static_cast<rlim_t>(fluorosim::memoryCapBytes() + kUnestimatedBytes);
    if (limit.rlim_max != RLIM_INFINITY && limit.rlim_max < want) return;  // a stricter limit is already set
    limit.rlim_cur = want;
    ::setrlimit(RLIMIT_DATA, &limit);
}

// Every message is one line of bounded length, whatever a library put into it.
std::string oneLine(const char* what) { return fluorosim::excerpt(what, 2000); }

// The exit code of a failure, printed on the root only (the other ranks hold the same failure).
int report(std::exception_ptr failure) {
    using namespace fluorosim;
    const bool print = cluster::isRoot();
    try {
        std::rethrow_exception(failure);
    } catch (const app::Interrupted& e) {
        if (print) std::fprintf(stderr, "fluorosim: %s\n", oneLine(e.what()).c_str());
        return 130;
    } catch (const ConfigError& e) {
        if (print) std::fprintf(stderr, "fluorosim: error: %s\n", oneLine(e.what()).c_str());
        return 2;
    } catch (const IoError& e) {
        if (print) std::fprintf(stderr, "fluorosim: I/O error: %s\n", oneLine(e.what()).c_str());
        return 3;
    } catch (const Error& e) {
        if (print) std::fprintf(stderr, "fluorosim: error: %s\n", oneLine(e.what()).c_str());
        return 4;
    } catch (const std::bad_alloc&) {
        // An allocation beyond the heap limit that no estimate caught: a resource failure, not a bug.
        if (print)
            std::fprintf(stderr, "fluorosim: error: out of memory: the run needed more than the memory cap of %s allows "
                                 "(raise it with --memory-cap or FLUOROSIM_MEMORY_CAP if the machine has the memory)\n",
                         formatBytes(static_cast<double>(memoryCapBytes())).c_str());
        return 4;
    } catch (const std::exception& e) {
        if (print) std::fprintf(stderr, "fluorosim: internal error: %s\n", oneLine(e.what()).c_str());
        return 5;
    }
}

int run(int argc, char** argv) {
    using namespace fluorosim;
    CLI::App app{"Fluorosim: spectral Monte Carlo simulation of fluorescence microscopy"};
    app.require_subcommand(1);
    // The global option is accepted after the subcommand too.
    app.fallthrough();
    std::string memoryCap;
    app.add_option("--memory-cap", memoryCap,
                   "Largest memory a run may plan to use, e.g. 16GiB (default: 8 GiB or half the RAM; env FLUOROSIM_MEMORY_CAP)");
    app.parse_complete_callback([&memoryCap] { applyMemoryCap(memoryCap); });
    app::addRenderCommand(app);
    app::addAcquireCommand(app);
    app::addValidateCommands(app);
    app::addVoxelizeCommand(app);
    app::addFitCommands(app);
#ifdef FLUOROSIM_WITH_VIEWER
    app::addViewCommand(app);
#endif
    for (CLI::App* command : app.get_subcommands([](CLI::App*) { return true; }))
        if (command->get_name() != "acquire" && command->get_name() != "render")
            command->preparse_callback([name = command->get_name()](size_t) {
                if (cluster::size() > 1)
                    throw ConfigError(name + " runs in one process; start it without mpirun (acquire and render distribute over MPI ranks)");
            });
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        // --help and --version exit 0 with CLI11's output; usage errors are invalid input (exit 2) on one
        // line. Every rank parses the same arguments; the root speaks for all.
        if (e.get_exit_code() == 0) return cluster::isRoot() ? app.exit(e) : 0;
        if (cluster::isRoot()) std::fprintf(stderr, "fluorosim: error: %s (see --help)\n", oneLine(e.what()).c_str());
        return 2;
    } catch (...) {
        std::exception_ptr failure = std::current_exception();
        // Ranks that failed before distributing any work meet the others at their agreement point.
        if (cluster::size() > 1 && !cluster::agreed()) {
            try {
                cluster::agree(failure);
            } catch (...) {
                failure = std::current_exception();
            }
        }
        const int code = report(failure);
        if (cluster::workersWaiting()) cluster::abortRun(code);
        return code;
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    fluorosim::cluster::start(argc, argv);
    const int code = run(argc, argv);
    fluorosim::cluster::finish();
    return code;
}
