// fluorosim: command-line front end. Library errors arrive as typed exceptions and become a
// one-line message and a non-zero exit code here. Under mpirun every rank runs this; only the root
// prints errors (cluster/cluster.h).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>

#include "cluster.h"
#include "commands.h"
#include "core/errors.h"

namespace {

using namespace fluorosim;

// The exit code of a failure, printed on the root only (the other ranks hold the same failure).
int report(std::exception_ptr failure) {
    const bool print = cluster::isRoot();
    try {
        std::rethrow_exception(failure);
    } catch (const app::Interrupted& e) {
        if (print) std::fprintf(stderr, "fluorosim: %s\n", e.what());
        return 130;
    } catch (const ConfigError& e) {
        if (print) std::fprintf(stderr, "fluorosim: error: %s\n", e.what());
        return 2;
    } catch (const IoError& e) {
        if (print) std::fprintf(stderr, "fluorosim: I/O error: %s\n", e.what());
        return 3;
    } catch (const Error& e) {
        if (print) std::fprintf(stderr, "fluorosim: error: %s\n", e.what());
        return 4;
    } catch (const std::exception& e) {
        if (print) std::fprintf(stderr, "fluorosim: internal error: %s\n", e.what());
        return 5;
    }
}

int run(int argc, char** argv) {
    CLI::App app{"Fluorosim: spectral Monte Carlo simulation of fluorescence microscopy"};
    app.require_subcommand(1);
    app::addRenderCommand(app);
    app::addAcquireCommand(app);
    app::addValidateCommands(app);
    app::addVoxelizeCommand(app);
    for (CLI::App* command : app.get_subcommands([](CLI::App*) { return true; }))
        if (command->get_name() != "acquire" && command->get_name() != "render")
            command->preparse_callback([name = command->get_name()](size_t) {
                if (cluster::size() > 1)
                    throw ConfigError(name + " runs in one process; start it without mpirun (acquire and render distribute over MPI ranks)");
            });
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        // Every rank parses the same arguments; the root speaks for all.
        return cluster::isRoot() ? app.exit(e) : e.get_exit_code();
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
