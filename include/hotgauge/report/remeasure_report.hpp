#pragma once
// The page of `hotgauge remeasure` (docs/results.md): the parts of a results folder measured
// again, compared with what the daemon said at the time (results::compare_parts). One
// self-contained HTML page like the lot report: inline CSS, no script, nothing fetched.
#include <cstddef>
#include <string>

#include "hotgauge/results/compare.hpp"

namespace hotgauge::report {

struct RemeasureInfo {
    std::string title = "Parts measured again";
    // Where the daemon's results were read, where the new ones are.
    std::string results_dir, out_dir;
    std::string recipe, calibration;  // what the parts were measured with ("" = as archived)
    std::size_t parts_in_range = 0, parts_measured = 0;
    double wall_s = 0;         // how long it took
    bool stopped = false;      // Ctrl-C before the end: the page says it covers only what was done
    std::string generated_at;  // local time text
};

// The page: what was measured with what, the summary (unchanged, flips by kind), the flips, the
// shift per feature (µm) and the parts not measured again with why. Every text is escaped.
std::string remeasure_html(const results::Comparison& c, const RemeasureInfo& info);

}  // namespace hotgauge::report
