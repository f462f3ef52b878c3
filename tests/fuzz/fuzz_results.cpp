// Fuzzes results::read_parts (a results folder's day file, docs/results.md) and what is made from
// what it reads: the lot report and the AQDEF export. Input: the whole day file. Asserts: no
// crash, sanitizer report or exception; an error names the file and line; every part read has its
// features' limits in order, and the page and the DFQ are made from them.
#include "fuzz_util.hpp"
#include "hotgauge/report/aqdef.hpp"
#include "hotgauge/report/lot_report.hpp"
#include "hotgauge/results/read_back.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const auto file = fuzz::input_file("results", "2026-12-04.jsonl", data, size);
    const auto dir = file.parent_path();
    auto read = fuzz::no_throw("read_parts", [&] { return results::read_parts(dir); });
    if (!read) {
        fuzz::check_error_names(read.error(),
                                read.error().message.starts_with(file.string()) ? file : dir);
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
