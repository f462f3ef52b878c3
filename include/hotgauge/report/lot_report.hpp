#pragma once
// The lot report (issue 19, docs/results.md "Lot report"): one self-contained HTML page over the
// parts of a results folder in a time range: per feature an individuals / moving-range chart
// with control limits from a baseline, Western Electric rule violations and the drift warning
// marked, a histogram against the tolerance, Cp/Cpk and Pp/Ppk, and the counts of each verdict
// with their reasons. Inline SVG, no script, nothing fetched: it opens from a USB stick.
#include <cstddef>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/quality/drift.hpp"
#include "hotgauge/quality/statistics.hpp"
#include "hotgauge/results/read_back.hpp"

namespace hotgauge::report {

struct LotOptions {
    // Control limits and the drift warning's baseline: the first values of each feature. With
    // fewer than quality::kMinBaseline measured values there are no limits, and the page says so.
    std::size_t baseline = 25;
    std::string title = "Lot report";
};

// One feature over the lot. Statistics use the values with verdict OK or NOK; degraded values
// (measured with untrusted data) are counted and listed, not used.
struct FeatureLot {
    std::string recipe, name;  // a feature of a recipe: recipes may share feature names
    std::string title;         // the name, with the recipe when the lot has several
    double nominal_mm = 0, lower_mm = 0, upper_mm = 0;  // limits as deviations from nominal
    std::vector<double> values;                         // cold, in part order
    std::vector<std::uint64_t> sequences;               // the part of each value
    std::map<std::string, std::size_t> verdicts;        // OK, NOK, NOT_MEASURED, DEGRADED
    std::map<std::string, std::size_t> reasons;         // grouped (reason_group)
    std::size_t baseline = 0;                           // values the limits come from
    std::optional<quality::IndividualsChart> chart;
    std::optional<quality::Capability> capability;
    std::vector<quality::RuleViolation> violations;
    std::optional<std::size_t> drift_at;  // index in values of the first drift warning
    quality::Drift first_drift = quality::Drift::kNone;  // its direction at drift_at
    quality::Drift drift = quality::Drift::kNone;        // at the lot's end
    std::string no_statistics;  // why there are no limits or indices, when there are none
};

// A type-1 gauge study from the master checks in the lot (docs/quality.md): one master's
// certified feature measured again and again. Values: the check's cold values measured OK or
// NOK; the reference is the certificate's value, T the recipe's tolerance width.
inline constexpr std::size_t kMinMasterChecks = 10;  // fewer: no study (VDA 5 asks for 25)
struct MasterStudy {
    std::string master, feature;
    double reference_mm = 0, tolerance_mm = 0;
    std::vector<double> values{};
    std::optional<quality::Type1Study> study{};
    std::string no_study{};  // why there is none
};

// A type-3 gauge study from repeat scans in the lot (docs/quality.md): production parts whose
// part id was measured more than once. r is the most common number of values measured OK or NOK
// per repeated part, and every part with at least r gives its first r; at least 5 such parts.
inline constexpr std::size_t kMinRepeatParts = 5;
struct RepeatStudy {
    std::string feature;
    double tolerance_mm = 0;
    std::size_t parts = 0, repeats = 0;
    std::optional<quality::Type3Study> study{};
    std::string no_study{};
};

struct Lot {
    std::size_t parts = 0, master_checks = 0;
    std::map<std::string, std::size_t> verdicts;  // of the parts
    std::string first_time, last_time;
    std::uint64_t first_sequence = 0, last_sequence = 0;
    std::vector<FeatureLot> features;  // in recipe order of the first part, then new ones
    std::vector<MasterStudy> masters;  // by master, then certificate order; per certified value
    std::vector<RepeatStudy> repeats;  // per feature, when some part was measured again
};

// The statistics of every feature of the production parts (master checks left out).
Lot summarize_lot(const std::vector<results::PartRecord>& parts, const LotOptions& options);

// A reason without its numbers: the text before the first ';' and the distinct causes after
// each "): " ("degraded: measured with untrusted profiles (accelerometer gap)").
std::string reason_group(const std::string& reason);

std::string lot_report_html(const Lot& lot, const LotOptions& options);

}  // namespace hotgauge::report
