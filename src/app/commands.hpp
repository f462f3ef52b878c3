#pragma once
// Subcommands of the engineer's tool `hotgauge`. Each registers itself on the CLI11 app and
// returns the process exit code when run.
#include <CLI/CLI.hpp>
#include <functional>

namespace hotgauge::app {

using Command = std::function<int()>;

Command add_simulate(CLI::App& app);
Command add_measure(CLI::App& app);
Command add_table1(CLI::App& app);
Command add_fit(CLI::App& app);
Command add_model(CLI::App& app);
Command add_grab(CLI::App& app);
Command add_plc(CLI::App& app);
Command add_calibrate(CLI::App& app);

}  // namespace hotgauge::app
