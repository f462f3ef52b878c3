#pragma once
// Parts measured again against what the daemon said at the time (`hotgauge remeasure`,
// docs/results.md): which verdicts changed, how far each feature's values moved, and which parts
// could not be measured again. Pure data: the caller reads and measures, this only compares.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/results/read_back.hpp"

namespace hotgauge::results {

// The verdict of a feature that one of the two measurements does not have (the recipe changed
// its features), in VerdictFlip::before or after.
inline constexpr const char* kAbsent = "ABSENT";

struct VerdictFlip {  // one feature of one part whose verdict changed
    std::uint64_t sequence = 0;
    std::string part_id, feature;
    std::string before, after;                  // verdicts
    std::optional<double> before_mm, after_mm;  // cold values
};
struct FeatureShift {  // one feature over the parts measured again (values measured both times)
    std::string feature;
    std::size_t n = 0;    // parts with a value before and after
    double mean_mm = 0;   // mean of (after - before)
    double worst_mm = 0;  // the shift with the largest |after - before| (signed)
    std::uint64_t worst_sequence = 0;
    std::string worst_part_id;
};
struct NotRemeasured {
    std::uint64_t sequence = 0;
    std::string part_id, why;
};
struct Comparison {
    std::size_t parts = 0;  // parts compared (in both before and after)
    // Parts whose every feature's verdict and value is the same to the bit and whose part verdict
    // is the same.
    std::size_t unchanged = 0;
    std::vector<VerdictFlip> part_flips;  // part verdict changes (feature field empty)
    std::vector<VerdictFlip> flips;       // feature verdict changes, by sequence then recipe order
    std::vector<FeatureShift> shifts;     // per feature, in the recipe's (first part's) order
    std::vector<NotRemeasured> not_remeasured;  // given by the caller, kept in order
    // Feature flips from `before` to `after` ("OK", "NOK": features the new measurement rejects).
    std::size_t count(const std::string& before, const std::string& after) const;
};

// Parts are paired by sequence; a part of `after` not in `before` (or vice versa) is an error in
// the caller, not here: pair what is in both. Master checks (PartRecord::master_check) are skipped.
// Features are paired by name within a part; one that only one side has is a flip to or from
// kAbsent. A feature's value counts in its shift when both sides have a cold value (degraded ones
// too: the same recording measured again, so the shift is the recipe's or calibration's).
Comparison compare_parts(const std::vector<PartRecord>& before,
                         const std::vector<PartRecord>& after,
                         std::vector<NotRemeasured> not_remeasured = {});

// For a terminal: counts, flips grouped OK→NOK / NOK→OK / other (at most 20 lines per group, then
// "… and N more"), the per-feature shift table (µm), then the parts not measured again with why.
// Columns are aligned and lines at most 100 characters: longer texts are cut with "…" (the JSON
// and the HTML page have them whole).
std::string comparison_table(const Comparison& c);
// The same as one JSON object (dump(2)): {"parts", "unchanged", "part_flips", "flips", "shifts",
// "not_remeasured"}; a flip is {"sequence", "part_id", "feature", "before", "after",
// "before_mm", "after_mm"} (a part flip's feature "" and values null), a missing value null, and
// a shift over no part has null mean, worst and part.
std::string comparison_json(const Comparison& c);

}  // namespace hotgauge::results
