#pragma once
// The raw archive (docs/results.md "Raw archive"): the recording of every NOK, degraded or
// unmeasured part and of every Nth OK part, kept under a disk quota, oldest deleted first, so
// that any archived part can be measured again (`hotgauge measure DIR`).
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/pipeline/pipeline.hpp"

namespace hotgauge::results {

struct ArchiveConfig {
    std::filesystem::path dir = "archive";
    std::uint64_t quota_bytes = 20ull << 30;  // all archived recordings together
    int every_nth_ok = 50;                    // 0: no OK part is kept
};

// Thread safety: one thread stores.
class RawArchive {
  public:
    static core::Result<RawArchive> open(const ArchiveConfig& config);

    // Whether this part's recording is kept: not OK (NOK, not measured), degraded, or the Nth OK.
    bool wants(const pipeline::PartResult& result, std::uint64_t sequence) const;
    // Writes the recording to DIR/YYYY-MM-DD/<sequence>_<part id>.partial/ and renames it to
    // .../<sequence>_<part id>/ (local date of time_ns) once whole, then deletes the oldest
    // recordings until the archive is within its quota (never the new one). Returns the new
    // recording's folder. A failure leaves no folder under the final name.
    core::Result<std::filesystem::path> store(const core::Recording& recording,
                                              std::uint64_t sequence, std::int64_t time_ns);
    // The folder store() writes for this part (so that a results line can name it first).
    std::filesystem::path folder(const std::string& part_id, std::uint64_t sequence,
                                 std::int64_t time_ns) const;
    // After a crash (or a store() that failed): every committed results line (JSON text,
    // results::last_result_lines) that names an archive folder which is not there (after a line
    // whose folder is, or with its .partial left: the quota deletes the oldest first) gets that
    // folder with a file NOT_ARCHIVED.txt saying `why`, and the .partial is deleted. A note that
    // cannot be written leaves no folder, for the next start to try again. Returns the folders
    // so marked.
    std::vector<std::filesystem::path> complete(const std::vector<std::string>& committed_lines);
    // A store() that failed while the daemon runs: the line's folder gets NOT_ARCHIVED.txt saying
    // `why` now. False when that could not be written either (the next start tries again).
    bool not_archived(const std::string& committed_line, const std::string& why);
    static constexpr const char* kNotArchived = "NOT_ARCHIVED.txt";
    // Bytes the archived recordings take now.
    std::uint64_t used_bytes() const;
    const ArchiveConfig& config() const { return config_; }

  private:
    explicit RawArchive(ArchiveConfig config) : config_(std::move(config)) {}
    ArchiveConfig config_;
};

}  // namespace hotgauge::results
