#include "hotgauge/results/results_log.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string_view>
#include <vector>

#include "hotgauge/core/log.hpp"

namespace hotgauge::results {
namespace {

spdlog::logger& log() {
    static const auto logger = core::module_logger("results");
    return *logger;
}

std::string errno_text(int e) { return std::strerror(e); }

// RFC 4180: quoted when it holds a comma, a quote or a line break; quotes doubled.
std::string cell(const std::string& s) {
    if (s.find_first_of(",\"\r\n") == std::string::npos) return s;
    std::string out = "\"";
    for (char c : s) {
        if (c == '"') out += '"';
        out += c;
    }
    return out + "\"";
}

std::string number(const std::optional<double>& v, int decimals) {
    if (!v || !std::isfinite(*v)) return "";
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.*f", decimals, *v);
    return buf;
}

std::tm local_tm(std::int64_t time_ns) {
    const std::time_t secs = static_cast<std::time_t>(time_ns / 1'000'000'000);
    std::tm tm{};
    localtime_r(&secs, &tm);
    return tm;
}

}  // namespace

std::string local_iso8601(std::int64_t time_ns) {
    const std::tm tm = local_tm(time_ns);
    char date[32], zone[8];
    std::strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%S", &tm);
    std::strftime(zone, sizeof zone, "%z", &tm);  // +0100
    const std::string z(zone);
    const long ms = static_cast<long>((time_ns / 1'000'000) % 1000);
    char out[64];
    std::snprintf(out, sizeof out, "%s.%03ld%s:%s", date, ms, z.substr(0, 3).c_str(),
                  z.substr(3).c_str());
    return out;
}

std::string local_date(std::int64_t time_ns) {
    const std::tm tm = local_tm(time_ns);
    char date[16];
    std::strftime(date, sizeof date, "%Y-%m-%d", &tm);
    return date;
}

std::string utc_iso8601(std::int64_t time_ns) {
    const std::time_t secs = static_cast<std::time_t>(time_ns / 1'000'000'000);
    std::tm tm{};
    gmtime_r(&secs, &tm);
    char date[32], out[48];
    std::strftime(date, sizeof date, "%Y-%m-%dT%H:%M:%S", &tm);
    std::snprintf(out, sizeof out, "%s.%03ldZ", date,
                  static_cast<long>((time_ns / 1'000'000) % 1000));
    return out;
}

// A spreadsheet user reads each row alone: per feature its value, deviation and verdict, the
// drawing's nominal and limits, and why it is not measured, NOK or degraded.
std::string csv_header(const pipeline::PartResult& r) {
    std::string h = "time,time_utc,sequence,part_id,recipe,temperature_c,verdict,degraded,drift";
    for (const auto& f : r.measurement.features)
        for (const char* column : {" value_mm", " deviation_mm", " verdict", " nominal_mm",
                                   " lower_limit_mm", " upper_limit_mm", " reason"})
            h += "," + cell(f.name + column);
    return h;
}

std::string csv_row(const ResultEntry& e) {
    const auto& r = *e.result;
    const auto& m = r.measurement;
    std::string row = local_iso8601(e.time_ns) + "," + utc_iso8601(e.time_ns) + "," +
                      std::to_string(e.sequence) + "," + cell(r.part_id) + "," + cell(r.recipe) +
                      "," + number(m.temperature_c, 1) + "," + measure::to_string(m.verdict) + "," +
                      (r.degraded ? "yes" : "no");
    std::string drifting;  // "Diameter 3 DRIFT_UP; …": the features the watch warns of
    for (const auto& [name, state] : e.drift)
        if (state.rfind("DRIFT", 0) == 0)
            drifting += (drifting.empty() ? "" : "; ") + name + " " + state;
    row += "," + cell(drifting);
    for (const auto& f : m.features) {
        // The value a quality engineer compares with the drawing: cold, in mm.
        row += "," + number(f.cold_mm, 4) + "," + number(f.deviation_mm, 4) + "," +
               measure::to_string(f.verdict) + "," + number(f.nominal_mm, 4) + "," +
               number(f.nominal_mm + f.tol_lower_mm, 4) + "," +
               number(f.nominal_mm + f.tol_upper_mm, 4) + "," + cell(f.reason);
    }
    return row;
}

namespace {

// A name as part of a file name: anything but letters, digits, '-' and '_' becomes '_' (a master
// serial "M/1" must not name a folder).
std::string file_safe(std::string name) {
    for (char& c : name)
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '_';
    return name.empty() ? "_" : name;
}

}  // namespace

std::string verification_csv_header(const pipeline::Verification& v) {
    std::string h = "time,sequence,master,part_id,recipe,passed";
    for (const auto& f : v.features) {
        h += "," + cell(f.name + " certified_mm");
        h += "," + cell(f.name + " deviation_mm");
        h += "," + cell(f.name + " passed");
    }
    return h;
}

std::string verification_csv_row(const ResultEntry& e) {
    const auto& v = *e.verification;
    std::string row = local_iso8601(e.time_ns) + "," + std::to_string(e.sequence) + "," +
                      cell(v.master) + "," + cell(e.result->part_id) + "," +
                      cell(e.result->recipe) + "," + (v.passed ? "yes" : "no");
    for (const auto& f : v.features)
        row += "," + number(std::optional<double>(f.certified_mm), 4) + "," +
               number(f.deviation_mm, 4) + "," + (f.passed ? "yes" : "no");
    return row;
}

std::string jsonl_line(const ResultEntry& e) {
    nlohmann::json j;
    j["time"] = local_iso8601(e.time_ns);
    j["time_ns"] = e.time_ns;
    j["sequence"] = e.sequence;
    j["software_version"] = e.software_version;
    j["config_hash"] = e.config_hash;
    j["result_hash"] = e.result_hash;
    j["archived_as"] = e.archived_as ? nlohmann::json(*e.archived_as) : nlohmann::json();
    j["die"] = e.die_id;
    j["drift"] = nlohmann::json::object();
    for (const auto& [name, state] : e.drift) j["drift"][name] = state;
    j["part"] = nlohmann::json::parse(pipeline::to_json(*e.result));
    if (e.verification)
        j["verification"] = nlohmann::json::parse(pipeline::to_json(*e.verification));
    return j.dump();  // one line: no indentation, line breaks in strings escaped
}

core::Result<ResultsLog> ResultsLog::open(const ResultsConfig& config) {
    std::error_code ec;
    std::filesystem::create_directories(config.dir, ec);
    if (ec)
        return core::make_error(config.dir.string() +
                                ": cannot create the results folder: " + ec.message());
    return ResultsLog(config);
}

ResultsLog::ResultsLog(ResultsLog&& o) noexcept
    : config_(std::move(o.config_)),
      files_(std::move(o.files_)),
      last_csv_(std::move(o.last_csv_)),
      last_jsonl_(std::move(o.last_jsonl_)) {
    o.files_.clear();
}

ResultsLog& ResultsLog::operator=(ResultsLog&& o) noexcept {
    if (this != &o) {
        close_all();
        config_ = std::move(o.config_);
        files_ = std::move(o.files_);
        last_csv_ = std::move(o.last_csv_);
        last_jsonl_ = std::move(o.last_jsonl_);
        o.files_.clear();
    }
    return *this;
}

ResultsLog::~ResultsLog() { close_all(); }

void ResultsLog::close_all() {
    for (auto& [path, f] : files_)
        if (f.fd >= 0) ::close(f.fd);
    files_.clear();
}

namespace {

// The end (just past the '\n') of the last line break before offset `end`, reading back a block
// at a time; 0 when there is none, -1 when the file cannot be read.
off_t line_end_before(int fd, off_t end) {
    std::string block(1 << 16, '\0');
    while (end > 0) {
        const off_t start = std::max<off_t>(0, end - static_cast<off_t>(block.size()));
        const auto n = static_cast<std::size_t>(end - start);
        if (::pread(fd, block.data(), n, start) != static_cast<ssize_t>(n)) return -1;
        const auto nl = std::string_view(block.data(), n).rfind('\n');
        if (nl != std::string_view::npos) return start + static_cast<off_t>(nl) + 1;
        end = start;
    }
    return 0;
}

// The sequence in the last whole line of a JSON-lines file, if it has one.
std::optional<std::uint64_t> last_sequence_in(const std::filesystem::path& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return std::nullopt;
    struct stat st {};
    std::optional<std::uint64_t> out;
    const off_t end = ::fstat(fd, &st) == 0 ? line_end_before(fd, st.st_size) : -1;
    const off_t start = end > 0 ? line_end_before(fd, end - 1) : -1;
    if (start >= 0) {
        std::string line(static_cast<std::size_t>(end - 1 - start), '\0');
        if (::pread(fd, line.data(), line.size(), start) == static_cast<ssize_t>(line.size())) {
            const auto j = nlohmann::json::parse(line, nullptr, false);
            if (j.is_object() && j.contains("sequence") && j["sequence"].is_number_unsigned())
                out = j["sequence"].get<std::uint64_t>();
        }
    }
    ::close(fd);
    return out;
}

}  // namespace

std::uint64_t last_sequence(const std::filesystem::path& dir) {
    std::error_code ec;
    std::vector<std::filesystem::path> days;
    for (const auto& e : std::filesystem::directory_iterator(dir, ec))
        if (e.path().extension() == ".jsonl") days.push_back(e.path());
    std::sort(days.begin(), days.end());
    for (auto it = days.rbegin(); it != days.rend(); ++it)
        if (auto seq = last_sequence_in(*it)) return *seq;
    return 0;
}

// Opens a day file for appending. A last line without its line break (the power went during a
// write) is cut off here, so every line in the file is whole.
core::Result<ResultsLog::OpenFile*> ResultsLog::file(const std::filesystem::path& path) {
    if (auto it = files_.find(path); it != files_.end()) return &it->second;
    // One file per day and kind: close yesterday's.
    if (files_.size() > 8) close_all();
    std::error_code ec;
    const bool existed = std::filesystem::exists(path, ec);
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (fd < 0) return core::make_error(path.string() + ": " + errno_text(errno));
    OpenFile f{fd, {}};
    struct stat st {};
    if (::fstat(fd, &st) == 0 && st.st_size > 0) {
        // Where the last whole line ends (a day's JSON file grows to tens of megabytes; only its
        // tail is read). Unreadable: left as it is.
        const off_t size = st.st_size;
        std::string block(1 << 16, '\0');
        off_t keep = line_end_before(fd, size);
        if (keep < 0) keep = size;
        if (keep < size) {
            log().warn("{}: cut a torn last line of {} bytes (a write was interrupted)",
                       path.string(), size - keep);
            if (::ftruncate(fd, keep) != 0) {
                const int e = errno;
                ::close(fd);
                return core::make_error(path.string() + ": cannot repair: " + errno_text(e));
            }
        }
        // The header is the first line.
        const auto head =
            static_cast<std::size_t>(std::min<off_t>(keep, static_cast<off_t>(block.size())));
        if (head > 0 && ::pread(fd, block.data(), head, 0) == static_cast<ssize_t>(head)) {
            const auto nl = std::string_view(block.data(), head).find('\n');
            if (nl != std::string_view::npos) f.header = block.substr(0, nl);
        }
    }
    if (!existed && config_.sync) {  // the new name must survive a power cut too
        const int dir = ::open(path.parent_path().c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
        if (dir >= 0) {
            ::fsync(dir);
            ::close(dir);
        }
    }
    return &files_.emplace(path, std::move(f)).first->second;
}

core::Result<void> ResultsLog::write_line(OpenFile& f, const std::filesystem::path& path,
                                          const std::string& line) {
    const std::string data = line + "\n";
    struct stat st {};
    const off_t before = ::fstat(f.fd, &st) == 0 ? st.st_size : -1;
    std::size_t done = 0;
    while (done < data.size()) {
        const ssize_t n = ::write(f.fd, data.data() + done, data.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            const int e = n < 0 ? errno : ENOSPC;
            // Never leave half a line: back to where this line started.
            if (before >= 0 && ::ftruncate(f.fd, before) != 0)
                log().error("{}: could not cut back a partial line: {}", path.string(),
                            errno_text(errno));
            return core::make_error(path.string() + ": " + errno_text(e));
        }
        done += static_cast<std::size_t>(n);
    }
    if (config_.sync && ::fdatasync(f.fd) != 0)
        return core::make_error(path.string() + ": not stored durably: " + errno_text(errno));
    return {};
}

core::Result<void> ResultsLog::append(const ResultEntry& e) {
    if (!e.result) return core::make_error("results: an entry without a result");
    const std::string date = local_date(e.time_ns);
    const std::string header =
        e.verification ? verification_csv_header(*e.verification) : csv_header(*e.result);
    std::filesystem::path csv =
        config_.dir / (date + (e.verification ? ".verification.csv" : ".csv"));
    auto f = file(csv);
    if (!f) return f.error();
    if (!(*f)->header.empty() && (*f)->header != header) {
        // Another recipe's features: its own file, so that every column keeps one meaning.
        // A master's check with other certified features: a file per master.
        csv = config_.dir /
              (e.verification ? date + ".verification." + file_safe(e.verification->master) + ".csv"
                              : date + "." + e.result->recipe + ".csv");
        f = file(csv);
        if (!f) return f.error();
        if (!(*f)->header.empty() && (*f)->header != header) {
            // Changed the same day (a recipe or certificate edited and reloaded): a file per
            // header, named by its hash, never rows under another header's columns.
            char tag[17];
            std::snprintf(tag, sizeof tag, "%016zx", std::hash<std::string>{}(header));
            csv.replace_extension(std::string(tag).substr(0, 8) + ".csv");
            f = file(csv);
            if (!f) return f.error();
        }
    }
    if ((*f)->header.empty()) {
        if (auto ok = write_line(**f, csv, header); !ok) return ok;
        (*f)->header = header;
    }
    // JSON first: if the disk fills between the two, the CSV (what people read) does not show a
    // part the full record lacks.
    const std::filesystem::path jsonl = config_.dir / (date + ".jsonl");
    auto j = file(jsonl);
    if (!j) return j.error();
    if (auto ok = write_line(**j, jsonl, jsonl_line(e)); !ok) return ok;
    if (auto ok = write_line(**f, csv, e.verification ? verification_csv_row(e) : csv_row(e)); !ok)
        return ok;
    last_csv_ = csv;
    last_jsonl_ = jsonl;
    return {};
}

}  // namespace hotgauge::results
