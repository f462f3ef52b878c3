// hotgauge report lot|part: the quality engineer's reports, self-contained HTML files
// (docs/results.md). `report part` is in cmd_report_part.cpp.
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "commands.hpp"
#include "hotgauge/report/lot_report.hpp"

namespace hotgauge::app {
namespace {

struct LotArgs {
    std::string results, out;
    results::TimeRange range;
    report::LotOptions options;
};

int fail(const std::string& why) {
    std::fprintf(stderr, "hotgauge report: %s\n", why.c_str());
    return 1;
}

int run_lot(const LotArgs& a) {
    const auto read = results::read_parts(a.results, a.range);
    if (!read) return fail(read.error().message);
    report::LotOptions options = a.options;
    options.title = "Lot report: " + a.results +
                    (a.range.from.empty() ? "" : ", from " + a.range.from) +
                    (a.range.to.empty() ? "" : " to " + a.range.to);
    const report::Lot lot = report::summarize_lot(read->parts, options);
    if (lot.parts == 0)
        return fail(a.results + ": no production part in the range (" +
                    std::to_string(read->lines) + " results read)");
    std::ofstream out(a.out, std::ios::binary);
    out << report::lot_report_html(lot, options);
    out.close();
    if (!out) return fail(a.out + ": cannot write");
    std::fprintf(stderr, "%s: %zu parts, %zu features, %zu master checks left out\n", a.out.c_str(),
                 lot.parts, lot.features.size(), lot.master_checks);
    return 0;
}

Command add_report_lot(CLI::App* r) {
    auto a = std::make_shared<LotArgs>();
    auto* lot = r->add_subcommand("lot", "lot report: SPC charts, capability, verdict counts");
    lot->add_option("results", a->results, "results folder (YYYY-MM-DD.jsonl files)")->required();
    lot->add_option("--out", a->out, "the HTML file to write")->required();
    lot->add_option("--from", a->range.from, "first local time, as a prefix: 2026-12-04[T06[:30]]");
    lot->add_option("--to", a->range.to, "last local time, as a prefix (included)");
    lot->add_option("--baseline", a->options.baseline,
                    "values per feature the control limits come from (at least 20)")
        ->capture_default_str()
        ->check(CLI::Range(std::size_t{quality::kMinBaseline}, std::size_t{1000000}));
    return [a] { return run_lot(*a); };
}

}  // namespace

Command add_report(CLI::App& app) {
    auto* report = app.add_subcommand("report", "reports for the quality engineer (HTML)");
    report->require_subcommand(1);
    auto commands = std::make_shared<std::vector<std::pair<CLI::App*, Command>>>();
    for (auto add : {add_report_lot, add_report_part}) {
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
