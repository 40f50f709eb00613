#pragma once
#include <CLI/CLI.hpp>
#include <stdexcept>

namespace fluorosim::app {

// A run stopped by SIGINT/SIGTERM after writing its finished work; main() exits with 130.
struct Interrupted : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// Each adds its subcommand; the callback throws fluorosim::Error on bad input.
void addRenderCommand(CLI::App& app);
void addAcquireCommand(CLI::App& app);
void addValidateCommands(CLI::App& app);
void addVoxelizeCommand(CLI::App& app);
// `fit` and `gradient`: concentrations from an observed stack, and the model's Jacobian.
void addFitCommands(CLI::App& app);
// `validate emission` and `validate sweep`, under the `validate` command.
void addFluorescenceValidations(CLI::App& validate);
// `validate lightsheet`.
void addLightSheetValidation(CLI::App& validate);
#ifdef FLUOROSIM_WITH_VIEWER
// `view`: the VTK viewer (built with the CMake option FLUOROSIM_WITH_VIEWER).
void addViewCommand(CLI::App& app);
#endif

}  // namespace fluorosim::app
