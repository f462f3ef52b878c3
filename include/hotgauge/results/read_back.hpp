#pragma once
// Reading the results files back (docs/results.md): one feature's values over the day files of a
// results folder, for the gauge studies and reports (docs/quality.md).
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::results {

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

// Every `*.jsonl` file of `dir`, in name order (YYYY-MM-DD sorts by day). A line repeated with the
// same sequence (an append retried after a full disk) counts once, the last. Errors name the
// folder, or the file and line that is not a result line; a feature that no part has is an error.
core::Result<FeatureSeries> read_feature_values(const std::filesystem::path& dir,
                                                const std::string& feature);

// The recording the daemon archived for part `sequence` (the `archived_as` of its results line,
// the last one if repeated), for `hotgauge report part --results`. A relative `archived_as` is
// taken as written, else relative to `dir`. Errors name the folder when no line has that
// sequence, and the file and line when the part was not archived or its recording is gone.
core::Result<std::filesystem::path> archived_recording(const std::filesystem::path& dir,
                                                       std::uint64_t sequence);

}  // namespace hotgauge::results
