#pragma once
// Results files for quality engineers (docs/results.md): per day, results/YYYY-MM-DD.csv with one
// row per part (time, sequence, part id, recipe, temperature, verdict, then value, deviation and
// verdict per feature: opens in a spreadsheet) and results/YYYY-MM-DD.jsonl with everything
// (the measure JSON of docs/measure-output.md plus sequence, software version, config hash).
//
// One commit per part (docs/results.md "One commit per part"): the part's JSON line, written and
// synced, is its commit; the CSV row is derived from that line. A line is never left half
// written: a failed write or sync is cut back, and a torn last line left by a power cut is cut
// off (and logged) when the file is next opened. A CSV row that a crash or a full disk kept out
// is written from its JSON line at the next append or open(). A full disk is an Error for the
// caller to report, never a crash; what was written before stays.
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
    // The part measured again because its first measurement, under this number, never committed
    // (a crash, FAULT 206): docs/results.md "One commit per part".
    std::optional<std::uint64_t> remeasure_of{};
    // What the PLC is shown (a JSON object's text, cell::plc_json), kept so that a part whose
    // result committed but never reached the PLC before a crash can be shown it again.
    std::string plc{};
};

namespace detail {
struct CsvLine;  // a CSV row derived from a JSON line (results_log.cpp)
}

// Thread safety: one thread appends.
class ResultsLog {
  public:
    // Creates the directory if needed; the error names it. Completes the CSV from the JSON: a
    // row of the last kRecoverLines committed parts that is missing from its CSV file (a crash
    // between the two, a power cut before the CSV reached the disk) is written, and logged.
    static core::Result<ResultsLog> open(const ResultsConfig& config);
    static constexpr std::size_t kRecoverLines = 64;
    ResultsLog(ResultsLog&&) noexcept;
    ResultsLog& operator=(ResultsLog&&) noexcept;
    ~ResultsLog();

    // Commits one part: its JSON line to the day's YYYY-MM-DD.jsonl (local date of time_ns),
    // written and synced; then its CSV row, not synced (a part of a recipe whose features
    // differ from the day's CSV header goes to YYYY-MM-DD.<recipe>.csv). An error means the part
    // was not committed: nothing of it is in the files; it names the file (e.g. "No space left
    // on device"). A CSV row that could not be written after the commit is owed, written before
    // the next part's, and named by csv_error().
    core::Result<void> append(const ResultEntry& entry);

    // The last append's CSV row to the disk: called once the PLC has the result, off its wait
    // (so a power cut can lose at most the newest part's row, which the next open() writes).
    void sync_csv();

    // The files the last append wrote (tests, logs), and its JSON line.
    const std::filesystem::path& last_csv() const { return last_csv_; }
    const std::filesystem::path& last_jsonl() const { return last_jsonl_; }
    const std::string& last_line() const { return last_line_; }
    // Why CSV rows of committed parts are owed ("" when none is): the last append's, or open()'s.
    const std::string& csv_error() const { return csv_error_; }
    // Sequences whose CSV rows open() wrote from their JSON lines (tests, logs).
    const std::vector<std::uint64_t>& completed_at_open() const { return completed_; }

  private:
    explicit ResultsLog(ResultsConfig config) : config_(std::move(config)) {}
    struct OpenFile {
        int fd = -1;
        std::string header;  // CSV: the header line it has
    };
    core::Result<OpenFile*> file(const std::filesystem::path& path);
    core::Result<void> write_line(OpenFile& f, const std::filesystem::path& path,
                                  const std::string& line, bool sync);
    core::Result<std::filesystem::path> csv_file(const detail::CsvLine& row);
    core::Result<void> write_csv(const detail::CsvLine& row);
    core::Result<void> write_owed();
    void complete_csv();
    void close_all();

    ResultsConfig config_;
    std::map<std::filesystem::path, OpenFile> files_;
    std::filesystem::path last_csv_, last_jsonl_;
    std::string last_line_, csv_error_;
    std::vector<std::string> owed_;  // JSON lines whose CSV rows are not written yet
    std::vector<std::uint64_t> completed_;
};

// The CSV header and row for a result (RFC 4180 quoting; empty cells for what was not
// measured). Exposed for tests and for `hotgauge` tools. The rows are derived from the entry's
// JSON line: csv_row(e) == csv_row_of_line(jsonl_line(e)), what open() writes for a missing row.
std::string csv_header(const pipeline::PartResult& result);
std::string csv_row(const ResultEntry& entry);
std::string jsonl_line(const ResultEntry& entry);
std::string verification_csv_header(const pipeline::Verification& verification);
std::string verification_csv_row(const ResultEntry& entry);  // entry.verification set
// The CSV row of a committed JSON line (a part's, or a master check's verification row); throws
// nlohmann::json::exception when it is not a result line.
std::string csv_row_of_line(const std::string& jsonl_line);
// The last `max` whole lines of the newest day files' (*.jsonl) in file order, oldest first:
// the committed parts a crash may have left unfinished (the CSV, the archive, the plant spool).
std::vector<std::string> last_result_lines(const std::filesystem::path& dir, std::size_t max);
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
