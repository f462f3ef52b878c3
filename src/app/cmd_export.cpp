// hotgauge export aqdef RESULTS --out FILE.dfq: the results as AQDEF (docs/results.md).
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>

#include "commands.hpp"
#include "hotgauge/report/aqdef.hpp"

namespace hotgauge::app {
namespace {

struct ExportArgs {
    std::string results, out;
    results::TimeRange range;
};

int run_aqdef(const ExportArgs& a) {
    const auto read = results::read_parts(a.results, a.range);
    if (!read) {
        std::fprintf(stderr, "hotgauge export: %s\n", read.error().message.c_str());
        return 1;
    }
    std::ofstream out(a.out, std::ios::binary);
    out << report::aqdef_dfq(read->parts);
    out.close();
    if (!out) {
        std::fprintf(stderr, "hotgauge export: %s: cannot write\n", a.out.c_str());
        return 1;
    }
    std::fprintf(stderr, "%s: %zu results from %zu files\n", a.out.c_str(), read->parts.size(),
                 read->files);
    return 0;
}

}  // namespace

Command add_export(CLI::App& app) {
    auto a = std::make_shared<ExportArgs>();
    auto* e = app.add_subcommand("export", "results in the formats of SPC tools (docs/results.md)");
    e->require_subcommand(1);
    auto* aqdef =
        e->add_subcommand("aqdef", "AQDEF (DFQ, K-field notation) for qs-STAT and others");
    aqdef->add_option("results", a->results, "results folder (YYYY-MM-DD.jsonl files)")->required();
    aqdef->add_option("--out", a->out, "the .dfq file to write")->required();
    aqdef->add_option("--from", a->range.from, "first local time, as a prefix: 2026-12-04[T06]");
    aqdef->add_option("--to", a->range.to, "last local time, as a prefix (included)");
    return [a] { return run_aqdef(*a); };
}

}  // namespace hotgauge::app
