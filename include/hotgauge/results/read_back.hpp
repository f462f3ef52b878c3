#pragma once
// Reading the results files back (docs/results.md): the parts of a results folder's day files,
// or one feature's values over them, for the gauge studies, the lot report and the AQDEF export
// (docs/quality.md).
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::results {

// One feature of one part, as the JSON line has it (docs/measure-output.md).
struct FeatureRecord {
    std::string name;
    int slot = 0;
    double nominal_mm = 0;
    double lower_mm = 0, upper_mm = 0;  // allowed deviations from nominal (tolerance_mm)
    std::optional<double> cold_mm;      // empty: not measured
    std::optional<double> u_cold_mm;
    std::string verdict;  // OK, NOK, NOT_MEASURED, DEGRADED
    std::string reason;   // why not measured / NOK / degraded; "" when none
    // The value statistics, studies and the drift watch use: measured OK or NOK (a degraded
    // value was measured with data the cell does not trust).
    std::optional<double> usable_mm() const {
        return verdict == "OK" || verdict == "NOK" ? cold_mm : std::nullopt;
    }
};

// One result line: a part, or a master check (`verification` in the line).
struct PartRecord {
    std::uint64_t sequence = 0;
    std::int64_t time_ns = 0;
    std::string time;  // as written: local time with its UTC offset
    std::string part_id, recipe, verdict;
    std::optional<double> temperature_c;
    bool master_check = false;
    int die = 0;                             // the die the PLC named, 0 when none
    std::vector<FeatureRecord> features;     // in recipe order
    std::optional<std::string> archived_as;  // the raw archive folder, as written; empty: none
    // A master check's master serial and certified values (feature name -> mm).
    std::string master;
    std::vector<std::pair<std::string, double>> certified;
};

// Which parts to read: by the local time as written, compared on the bound's length, both ends
// included: from "2026-12-04" to "2026-12-04" is that day, from "2026-12-04T06" to
// "2026-12-04T13" a shift. Empty: no bound.
struct TimeRange {
    std::string from, to;
    bool contains(const std::string& time) const;
};

// One line of a day file as a PartRecord; throws nlohmann::json::exception when it is not a
// result line. For the daemon's own lines (the lot report it keeps).
PartRecord parse_result_line(std::string_view line);

struct PartsRead {
    std::vector<PartRecord> parts;  // in file order (days by name), one per sequence number
    std::size_t files = 0, lines = 0;
    std::vector<std::string> skipped;  // with skip_bad_lines: "file:line: why" of each
};

// Every `*.jsonl` file of `dir`, in name order (YYYY-MM-DD sorts by day; a day file outside the
// range is not opened). A line repeated with the same sequence (an append retried after a full
// disk) counts once, the last. Errors name the folder, or the file and line that is not a result
// line; with `skip_bad_lines` such a line is left out and named in `skipped` (the daemon, which
// must go on with what it can read).
core::Result<PartsRead> read_parts(const std::filesystem::path& dir, const TimeRange& range = {},
                                   bool skip_bad_lines = false);
// The lines of one day file's text, `file` naming it in errors.
core::Result<PartsRead> parse_parts(std::string_view text, const std::filesystem::path& file,
                                    const TimeRange& range = {}, bool skip_bad_lines = false);

struct FeatureValue {
    std::uint64_t sequence = 0;
    std::string time;  // as written: local time with its UTC offset
    std::string part_id;
    std::optional<double> cold_mm;  // empty: not measured
    std::string verdict;            // OK, NOK, NOT_MEASURED, DEGRADED
};

struct FeatureSeries {
    std::vector<FeatureValue> values;  // in file order (days by name), one per sequence number
    std::size_t files = 0, lines = 0;
    std::size_t without_feature = 0;  // parts whose recipe has no such feature
};

// One feature's values over read_parts(dir) (master checks included: a type-1 study takes the
// master's); a feature that no part has is an error.
core::Result<FeatureSeries> read_feature_values(const std::filesystem::path& dir,
                                                const std::string& feature);

// The recording the daemon archived for part `sequence` (the `archived_as` of its results line,
// the last one if repeated), for `hotgauge report part --results`. A relative `archived_as` is
// taken as written, else relative to `dir`. Errors name the folder when no line has that
// sequence, and the file and line when the part was not archived or its recording is gone.
core::Result<std::filesystem::path> archived_recording(const std::filesystem::path& dir,
                                                       std::uint64_t sequence);
// The recording folder of a part read from `dir` (its `archived_as`), with the same checks and
// errors as archived_recording; `where` names the part's line ("file:line") in them.
core::Result<std::filesystem::path> archived_folder(const std::filesystem::path& dir,
                                                    const PartRecord& part,
                                                    const std::string& where);

}  // namespace hotgauge::results
