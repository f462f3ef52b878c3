// Fuzzes results::parse_parts (a results folder's day file, docs/results.md) and what is made from
// what it reads: the lot report and the AQDEF export. Input: the whole day file, named
// fuzz/2026-12-04.jsonl. Asserts: no crash, sanitizer report or exception; an error names the
// file and line; the page and the DFQ are made from every part read.
#include "fuzz_util.hpp"
#include "hotgauge/report/aqdef.hpp"
#include "hotgauge/report/lot_report.hpp"
#include "hotgauge/results/read_back.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const auto file = fuzz::kDir / "2026-12-04.jsonl";
    auto read = fuzz::no_throw(
        "parse_parts", [&] { return results::parse_parts(fuzz::text_of(data, size), file); });
    if (!read) {
        fuzz::check_error_names(read.error(), file);
        return 0;
    }
    static_cast<void>(fuzz::no_throw("lot report", [&] {
        const auto lot = report::summarize_lot(read->parts, {.baseline = 20});
        fuzz::check(!report::lot_report_html(lot, {}).empty(), "an empty page");
        return core::Result<void>{};
    }));
    static_cast<void>(fuzz::no_throw("aqdef", [&] {
        fuzz::check(report::aqdef_dfq(read->parts).starts_with("K0100 "), "no K0100");
        return core::Result<void>{};
    }));
    return 0;
}
