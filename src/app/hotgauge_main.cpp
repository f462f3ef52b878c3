// hotgauge: the engineer's tool (docs/architecture.md). Exit codes: 0 success, 1 the job failed
// (bad input, nothing measured), 2 bad command line.
#include <spdlog/cfg/env.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "commands.hpp"

int main(int argc, char** argv) {
    spdlog::set_default_logger(spdlog::stderr_color_mt("hotgauge"));
    spdlog::cfg::load_env_levels();  // SPDLOG_LEVEL=debug
    CLI::App app{"hotgauge: measure hot forgings, simulate the cell, inspect recordings"};
    app.require_subcommand(1);
    std::vector<std::pair<CLI::App*, hotgauge::app::Command>> commands;
    auto add = [&](auto fn) {
        const auto before = app.get_subcommands({}).size();
        auto cmd = fn(app);
        commands.emplace_back(app.get_subcommands({})[before], std::move(cmd));
    };
    add(hotgauge::app::add_simulate);
    add(hotgauge::app::add_measure);
    add(hotgauge::app::add_table1);
    add(hotgauge::app::add_fit);
    add(hotgauge::app::add_model);
    add(hotgauge::app::add_grab);
    add(hotgauge::app::add_plc);
    add(hotgauge::app::add_calibrate);
    add(hotgauge::app::add_verify);
    add(hotgauge::app::add_study);
    add(hotgauge::app::add_report);
    add(hotgauge::app::add_export);
    add(hotgauge::app::add_remeasure);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e) == 0 ? 0 : 2;
    }
    for (auto& [sub, run] : commands)
        if (sub->parsed()) return run();
    return 2;
}
