#pragma once
#include <CLI/CLI.hpp>

namespace fluorosim::app {

// Each adds its subcommand; the callback throws fluorosim::Error on bad input.
void addRenderCommand(CLI::App& app);
void addValidateCommands(CLI::App& app);

}  // namespace fluorosim::app
