#pragma once
// What the status page shows (docs/operations.md "Status page"), kept by the daemon as things
// happen: its state, each part's result as written to the results files, faults, device health,
// the last scanned part's range images. web::Server asks for a snapshot (view) per request.
// Thread safety: every member may be called from any thread; part() draws the pictures before
// it takes the lock, so a request never waits for the drawing.
#include <cstdint>
#include <deque>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/cell/health.hpp"
#include "hotgauge/core/recording.hpp"
#include "hotgauge/web/cell_view.hpp"
#include "hotgauge/web/server.hpp"

namespace hotgauge::cell {

// One part's outcome, as the processing thread has it after the registers.
struct PartNews {
    std::string jsonl_line;  // its line in the day's .jsonl (results::jsonl_line)
    std::string outcome;     // what the PLC got: the verdict, or the fault and why
    std::string message;     // the journal's line: goes to the faults when `problem`
    bool problem = false;
    const core::Recording* recording = nullptr;     // its scans: the pictures (none: keep the last)
    std::vector<std::filesystem::path> files;       // the day's CSV and JSONL it went to
    std::optional<std::filesystem::path> archived;  // the archive folder of its recording
};

class StatusBoard {
  public:
    StatusBoard(const std::filesystem::path& results_dir, const std::filesystem::path& archive_dir,
                std::size_t keep_results = 10, std::size_t keep_events = 30);

    // The folders the page links into, by URL prefix: for web::ServerConfig::roots.
    std::vector<web::FileRoot> roots() const;

    void set_state(const std::string& state);
    void set_health(const DeviceHealth& health);
    void part(const PartNews& news);
    void event(const std::string& text, bool fault);
    // The snapshot (plc_state is the caller's: the PLC server knows it).
    web::CellView view() const;

  private:
    std::string href(const std::filesystem::path& file) const;  // "" when not under a root
    std::filesystem::path results_dir_, archive_dir_;
    std::size_t keep_results_, keep_events_;
    mutable std::mutex mutex_;
    web::CellView view_;
    DeviceHealth health_;
    std::vector<std::filesystem::path> day_files_;
    std::deque<std::filesystem::path> archived_;  // newest first
    std::string day_;                             // YYYY-MM-DD of the last result
};

}  // namespace hotgauge::cell
