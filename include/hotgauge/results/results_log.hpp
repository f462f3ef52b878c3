#pragma once
// Results files for quality engineers (docs/results.md): per day, results/YYYY-MM-DD.csv with one
// row per part (time, sequence, part id, recipe, temperature, verdict, then value, deviation and
// verdict per feature: opens in a spreadsheet) and results/YYYY-MM-DD.jsonl with everything
// (the measure JSON of docs/measure-output.md plus sequence, software version, config hash).
//
// Appends are durable before append() returns (write, then fdatasync), and a line is never left
// half written: a failed write is cut back, and a torn last line left by a power cut is cut off
// (and logged) when the file is next opened. A full disk is an Error for the caller to report,
// never a crash; what was written before stays.
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hotgauge/core/result.hpp"
#include "hotgauge/pipeline/pipeline.hpp"
#include "hotgauge/pipeline/verify.hpp"

namespace hotgauge::results {

struct ResultsConfig {
    std::filesystem::path dir = "results";
    bool sync = true;  // fdatasync each append (off only for benchmarks)
};

// One part, as it goes into the files.
struct ResultEntry {
    std::int64_t time_ns = 0;  // when the result became final (CLOCK_REALTIME)
    std::uint64_t sequence = 0;
    const pipeline::PartResult* result = nullptr;  // the measurement; required
    std::string software_version;
    std::string config_hash;
    std::optional<std::string> archived_as;  // where the raw recording was kept, if it was
    // A master part's check (docs/verification.md): its row goes to YYYY-MM-DD.verification.csv
    // and its JSON line carries "verification".
    const pipeline::Verification* verification = nullptr;
    int die_id = 0;  // the die the PLC named (0: not named)
    // The drift watch's state per feature after this part (docs/quality.md "In the daemon"):
    // feature name -> BASELINE, WATCHING, DRIFT_UP, DRIFT_DOWN. Empty: no watch.
    std::vector<std::pair<std::string, std::string>> drift{};
    std::string result_hash{};  // over everything that decided it (cell::Setup::result_hash)
};

// Thread safety: one thread appends.
class ResultsLog {
  public:
    // Creates the directory if needed; the error names it.
    static core::Result<ResultsLog> open(const ResultsConfig& config);
    ResultsLog(ResultsLog&&) noexcept;
    ResultsLog& operator=(ResultsLog&&) noexcept;
    ~ResultsLog();

    // Appends one CSV row and one JSON line to the day's files (local date of time_ns). A part
    // of a recipe whose features differ from the day's CSV header goes to
    // YYYY-MM-DD.<recipe>.csv. Errors name the file (e.g. "No space left on device").
    core::Result<void> append(const ResultEntry& entry);

    // The files the last append wrote (tests, logs).
    const std::filesystem::path& last_csv() const { return last_csv_; }
    const std::filesystem::path& last_jsonl() const { return last_jsonl_; }

  private:
    explicit ResultsLog(ResultsConfig config) : config_(std::move(config)) {}
    struct OpenFile {
        int fd = -1;
        std::string header;  // CSV: the header line it has
    };
    core::Result<OpenFile*> file(const std::filesystem::path& path);
    core::Result<void> write_line(OpenFile& f, const std::filesystem::path& path,
                                  const std::string& line);
    void close_all();

    ResultsConfig config_;
    std::map<std::filesystem::path, OpenFile> files_;
    std::filesystem::path last_csv_, last_jsonl_;
};

// The CSV header and row for a result (RFC 4180 quoting; empty cells for what was not
// measured). Exposed for tests and for `hotgauge` tools.
std::string csv_header(const pipeline::PartResult& result);
std::string csv_row(const ResultEntry& entry);
std::string jsonl_line(const ResultEntry& entry);
std::string verification_csv_header(const pipeline::Verification& verification);
std::string verification_csv_row(const ResultEntry& entry);  // entry.verification set
// The sequence number of the newest part in the results folder (the last line of the newest
// day's JSON file that has one; only file tails are read), 0 when there is none: numbering goes
// on from there after a restart.
std::uint64_t last_sequence(const std::filesystem::path& dir);

// "2026-11-22T07:15:03.123+01:00" (local time with its offset), "2026-11-22T06:15:03.123Z" (UTC)
// and "2026-11-22" (local date).
std::string utc_iso8601(std::int64_t time_ns);
std::string local_iso8601(std::int64_t time_ns);
std::string local_date(std::int64_t time_ns);

}  // namespace hotgauge::results
