// fluorosim: command-line front end. Library errors arrive as typed exceptions and become a
// one-line message and a non-zero exit code here.
#include <CLI/CLI.hpp>
#include <cstdio>

#include "commands.h"
#include "core/errors.h"

int main(int argc, char** argv) {
    CLI::App app{"Fluorosim: spectral Monte Carlo simulation of fluorescence microscopy"};
    app.require_subcommand(1);
    fluorosim::app::addRenderCommand(app);
    fluorosim::app::addAcquireCommand(app);
    fluorosim::app::addValidateCommands(app);
    fluorosim::app::addVoxelizeCommand(app);
#ifdef FLUOROSIM_WITH_VIEWER
    fluorosim::app::addViewCommand(app);
#endif
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e);
    } catch (const fluorosim::app::Interrupted& e) {
        std::fprintf(stderr, "fluorosim: %s\n", e.what());
        return 130;
    } catch (const fluorosim::ConfigError& e) {
        std::fprintf(stderr, "fluorosim: error: %s\n", e.what());
        return 2;
    } catch (const fluorosim::IoError& e) {
        std::fprintf(stderr, "fluorosim: I/O error: %s\n", e.what());
        return 3;
    } catch (const fluorosim::Error& e) {
        std::fprintf(stderr, "fluorosim: error: %s\n", e.what());
        return 4;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "fluorosim: internal error: %s\n", e.what());
        return 5;
    }
    return 0;
}
