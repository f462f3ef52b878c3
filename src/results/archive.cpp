#include "hotgauge/results/archive.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <vector>

#include "hotgauge/core/clock.hpp"
#include "hotgauge/core/log.hpp"
#include "hotgauge/io/recording_io.hpp"
#include "hotgauge/results/results_log.hpp"

namespace hotgauge::results {
namespace {

namespace fs = std::filesystem;

spdlog::logger& log() {
    static const auto logger = core::module_logger("results");
    return *logger;
}

std::uint64_t tree_bytes(const fs::path& dir) {
    std::uint64_t total = 0;
    std::error_code ec;
    for (auto it = fs::recursive_directory_iterator(dir, ec);
         !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
        if (it->is_regular_file(ec)) total += it->file_size(ec);
    return total;
}

// A part id as a folder name: letters, digits, '-', '_' and '.' kept, anything else '_'.
std::string safe_name(const std::string& s) {
    std::string out;
    for (char c : s)
        out += (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.')
                   ? c
                   : '_';
    return out.empty() ? "part" : out;
}

// Every archived recording: DIR/<date>/<sequence>_<id>; names sort oldest first (the date, then
// the zero-padded sequence).
std::vector<fs::path> recordings(const fs::path& dir) {
    std::vector<fs::path> out;
    std::error_code ec;
    for (const auto& day : fs::directory_iterator(dir, ec)) {
        if (!day.is_directory(ec)) continue;
        for (const auto& rec : fs::directory_iterator(day.path(), ec))
            if (rec.is_directory(ec)) out.push_back(rec.path());
    }
    std::sort(out.begin(), out.end());
    return out;
}

// A file or a folder (its entries) to the disk; the error, or "" when synced.
std::string sync_path(const fs::path& p, bool folder) {
    const int fd = ::open(p.c_str(), O_RDONLY | O_CLOEXEC | (folder ? O_DIRECTORY : 0));
    const bool ok = fd >= 0 && ::fsync(fd) == 0;
    const std::string why = ok ? "" : p.string() + ": " + std::strerror(errno);
    if (fd >= 0) ::close(fd);
    return why;
}

// Every file and folder under `dir`, then `dir`, to the disk: a recording renamed to its final
// name is whole after a power cut too. The first error, or "".
std::string sync_tree(const fs::path& dir) {
    std::string why;
    std::error_code ec;
    for (auto it = fs::recursive_directory_iterator(dir, ec);
         !ec && it != fs::recursive_directory_iterator() && why.empty(); it.increment(ec))
        why = sync_path(it->path(), it->is_directory(ec));
    if (why.empty() && ec) why = dir.string() + ": " + ec.message();
    return why.empty() ? sync_path(dir, true) : why;
}

}  // namespace

core::Result<RawArchive> RawArchive::open(const ArchiveConfig& config) {
    std::error_code ec;
    fs::create_directories(config.dir, ec);
    if (ec)
        return core::make_error(config.dir.string() +
                                ": cannot create the archive folder: " + ec.message());
    if (config.every_nth_ok < 0) return core::make_error("archive.every_nth_ok: must be >= 0");
    return RawArchive(config);
}

bool RawArchive::wants(const pipeline::PartResult& r, std::uint64_t sequence) const {
    if (r.measurement.verdict != measure::Verdict::kOk || r.degraded) return true;
    // Measured around untrusted profiles: the evidence that the gap bridging held.
    for (const auto& c : r.compensation)
        if (c.n_degraded > 0) return true;
    return config_.every_nth_ok > 0 &&
           sequence % static_cast<std::uint64_t>(config_.every_nth_ok) == 0;
}

std::uint64_t RawArchive::used_bytes() const { return tree_bytes(config_.dir); }

fs::path RawArchive::folder(const std::string& part_id, std::uint64_t sequence,
                            std::int64_t time_ns) const {
    char seq[32];
    std::snprintf(seq, sizeof seq, "%012llu", static_cast<unsigned long long>(sequence));
    return config_.dir / local_date(time_ns) / (std::string(seq) + "_" + safe_name(part_id));
}

core::Result<fs::path> RawArchive::store(const core::Recording& rec, std::uint64_t sequence,
                                         std::int64_t time_ns) {
    const fs::path where = folder(rec.part_id, sequence, time_ns);
    fs::path partial = where;
    partial += ".partial";
    std::error_code ec;
    fs::remove_all(partial, ec);
    if (auto ok = io::write_recording(rec, partial); !ok) {
        fs::remove_all(partial, ec);
        return ok.error();
    }
    if (const std::string why = sync_tree(partial); !why.empty()) {
        fs::remove_all(partial, ec);
        return core::make_error("not stored durably: " + why);
    }
    if (fs::rename(partial, where, ec); ec) {
        fs::remove_all(partial, ec);
        return core::make_error(where.string() + ": " + ec.message());
    }
    if (const std::string why = sync_path(where.parent_path(), true); !why.empty())
        log().warn("{}: the new name may not survive a power cut", why);
    // Within the quota again: oldest first, never the one just written.
    std::uint64_t used = used_bytes();
    for (const auto& old : recordings(config_.dir)) {
        if (used <= config_.quota_bytes) break;
        if (old == where) continue;
        const std::uint64_t size = tree_bytes(old);
        fs::remove_all(old, ec);
        if (ec) {
            log().error("{}: cannot delete for the archive quota: {}", old.string(), ec.message());
            break;
        }
        used -= std::min(used, size);
        log().info("archive quota: deleted {} ({} bytes)", old.string(), size);
        fs::remove(old.parent_path(), ec);  // the day folder, once empty (fails otherwise)
    }
    return where;
}

std::vector<fs::path> RawArchive::complete(const std::vector<std::string>& lines) {
    // A folder missing after one still there, or with its .partial left: never written. The
    // quota deletes the oldest first, so one missing before every folder still there (and without
    // a .partial) was deleted for it.
    std::vector<fs::path> marked;
    std::error_code ec;
    bool after_one_there = false;
    for (const auto& text : lines) {
        const auto j = nlohmann::json::parse(text, nullptr, false);
        if (!j.is_object() || !j.contains("archived_as") || !j["archived_as"].is_string()) continue;
        const std::string where = j["archived_as"].get<std::string>();
        if (fs::exists(where, ec))
            after_one_there = true;
        else if ((after_one_there || fs::exists(where + ".partial", ec)) &&
                 not_archived(
                     text,
                     "hotgauged stopped (a crash, a kill, a power cut) after the part's result "
                     "was committed and before its recording was written; found at the next "
                     "start"))
            marked.push_back(where);
    }
    return marked;
}

// The line's folder with NOT_ARCHIVED.txt saying why (its .partial deleted); no folder when the
// note cannot be written.
bool RawArchive::not_archived(const std::string& line, const std::string& why) {
    const auto j = nlohmann::json::parse(line, nullptr, false);
    if (!j.is_object() || !j.contains("archived_as") || !j["archived_as"].is_string()) return false;
    const fs::path where = j["archived_as"].get<std::string>();
    std::error_code ec;
    fs::remove_all(where.string() + ".partial", ec);
    fs::create_directories(where, ec);
    std::ofstream out(where / kNotArchived);
    out << "The raw recording of part " << j.value("/part/part_id"_json_pointer, std::string())
        << " (sequence " << j.value("sequence", 0ull) << ", " << j.value("time", std::string())
        << ") was not archived: " << why << " (noted " << core::iso8601_utc(core::realtime_ns())
        << "). The part's result is in the results files.\n";
    out.close();
    if (!out) {
        fs::remove_all(where, ec);
        log().error("{}: the part's recording is not there, and this could not be said in it",
                    where.string());
        return false;
    }
    log().warn("{}: the part's recording is not there ({}); {} says so", where.string(), why,
               kNotArchived);
    return true;
}

}  // namespace hotgauge::results
