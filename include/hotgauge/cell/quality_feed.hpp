#pragma once
// What the daemon keeps for the quality engineer beside the results files (docs/quality.md
// "In the daemon"): the drift watch per die, recipe and feature, whose state goes with every
// result (results files, PLC registers), and the day's lot report, rewritten after every part.
// Processing thread only.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hotgauge/pipeline/pipeline.hpp"
#include "hotgauge/quality/drift.hpp"
#include "hotgauge/results/read_back.hpp"

namespace hotgauge::cell {

struct QualityConfig {
    std::size_t drift_baseline = 100;  // values per die and feature before watching; 0: no watch
    bool lot_report = true;            // results/YYYY-MM-DD.report.html
    // The page is written at most this often (a page of 2 000 parts is 1.4 MB: written after
    // every part that would be ~3 GB a day); the parts in between come with the next write, the
    // day's last with the day change or the daemon's stop.
    double lot_report_every_s = 30;
};

class QualityFeed {
  public:
    QualityFeed(const std::filesystem::path& results_dir, const QualityConfig& config);
    ~QualityFeed();  // writes the page if parts came since the last write
    QualityFeed(const QualityFeed&) = delete;
    QualityFeed& operator=(const QualityFeed&) = delete;

    // Start and reload: the drift watch as it was after the last part (results/
    // drift-watch.json, written after every part), or, without that file, rebuilt from the last
    // 3 day files; and today's parts for the report. Lines that are not results (a torn line of
    // an older day) are logged and skipped.
    void load(std::int64_t now_ns);
    // Each feature's drift state after this production part (features measured OK or NOK feed
    // the watch; the others keep their state). Empty without a watch.
    std::vector<std::pair<std::string, std::string>> observe(int die,
                                                             const pipeline::PartResult& r);
    // The part's results line, once stored: today's report rewritten when lot_report_every_s has
    // passed since the last write (write, then rename, so a reader never sees half a page). A
    // failure is logged; measuring goes on.
    void stored(const std::string& jsonl_line, std::int64_t time_ns);

  private:
    void write_report();
    bool restore_watch();     // from results/drift-watch.json; false: no (usable) file
    void save_watch() const;  // after every part
    std::filesystem::path dir_;
    QualityConfig config_;
    std::optional<quality::DriftWatch> watch_;
    std::string today_;  // local date of the parts below
    std::vector<results::PartRecord> parts_;
    bool unwritten_ = false;  // parts came since the page was last written
    // When the page was last written; unset: never (the steady clock starts at boot, so a
    // machine up for less than lot_report_every_s would otherwise wait for its first page).
    std::optional<std::chrono::steady_clock::time_point> written_;
};

}  // namespace hotgauge::cell
