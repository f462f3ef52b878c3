// hotgauge report part|…: the quality engineer's reports, self-contained HTML files
// (docs/results.md).
#include <memory>
#include <utility>
#include <vector>

#include "commands.hpp"

namespace hotgauge::app {

Command add_report(CLI::App& app) {
    auto* report = app.add_subcommand("report", "reports for the quality engineer (HTML)");
    report->require_subcommand(1);
    auto commands = std::make_shared<std::vector<std::pair<CLI::App*, Command>>>();
    for (auto add : {add_report_part}) {
        Command run = add(report);
        commands->emplace_back(report->get_subcommands({}).back(), std::move(run));
    }
    return [commands] {
        for (const auto& [sub, run] : *commands)
            if (sub->parsed()) return run();
        return 2;
    };
}

}  // namespace hotgauge::app
