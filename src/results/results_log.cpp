#include "hotgauge/results/results_log.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
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

}  // namespace

// The columns before the features'.
constexpr const char* kPartColumns =
    "time,time_utc,sequence,part_id,recipe,temperature_c,verdict,degraded,drift,remeasure_of";

// A spreadsheet user reads each row alone: per feature its value, deviation and verdict, the
// drawing's nominal and limits, and why it is not measured, NOK or degraded.
std::string csv_header(const pipeline::PartResult& r) {
    std::string h = kPartColumns;
    for (const auto& f : r.measurement.features)
        for (const char* column : {" value_mm", " deviation_mm", " verdict", " nominal_mm",
                                   " lower_limit_mm", " upper_limit_mm", " reason"})
            h += "," + cell(f.name + column);
    return h;
}

std::string verification_csv_header(const pipeline::Verification& v) {
    std::string h = "time,sequence,master,part_id,recipe,passed";
    for (const auto& f : v.features)
        for (const char* column : {" certified_mm", " deviation_mm", " passed"})
            h += "," + cell(f.name + column);
    return h;
}

namespace {

// A name as part of a file name: anything but letters, digits, '-' and '_' becomes '_' (a master
// serial "M/1" must not name a folder).
std::string file_safe(std::string name) {
    for (char& c : name)
        if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '_';
    return name.empty() ? "_" : name;
}

using nlohmann::json;

std::optional<double> number_in(const json& v) {
    return v.is_number() ? std::optional<double>(v.get<double>()) : std::nullopt;
}
std::string text_in(const json& v) { return v.is_string() ? v.get<std::string>() : ""; }

json entry_json(const ResultEntry& e) {
    json j;
    j["time"] = local_iso8601(e.time_ns);
    j["time_ns"] = e.time_ns;
    j["sequence"] = e.sequence;
    j["software_version"] = e.software_version;
    j["config_hash"] = e.config_hash;
    j["result_hash"] = e.result_hash;
    j["archived_as"] = e.archived_as ? json(*e.archived_as) : json();
    j["die"] = e.die_id;
    j["drift"] = json::object();
    for (const auto& [name, state] : e.drift) j["drift"][name] = state;
    j["remeasure_of"] = e.remeasure_of ? json(*e.remeasure_of) : json();
    j["part"] = json::parse(pipeline::to_json(*e.result));
    if (!e.plc.empty()) j["plc"] = json::parse(e.plc);
    if (e.verification) j["verification"] = json::parse(pipeline::to_json(*e.verification));
    return j;
}

}  // namespace

// A part's CSV row (or a master check's verification row), derived from its JSON line alone:
// the row the append writes and the row open() writes for a part a crash left out are one.
struct detail::CsvLine {
    std::uint64_t sequence = 0;
    std::string date;  // local date: the day's files
    std::string header, row;
    std::string recipe;                 // a part's: its own file when the day's header differs
    std::optional<std::string> master;  // a master check's serial: the verification files

    static CsvLine of(const json& j);
    static CsvLine of_part(const json& j);
    static CsvLine of_check(const json& j);
};

detail::CsvLine detail::CsvLine::of(const json& j) {
    CsvLine c = j.contains("verification") ? of_check(j) : of_part(j);
    c.sequence = j.at("sequence").get<std::uint64_t>();
    c.date = local_date(j.at("time_ns").get<std::int64_t>());
    return c;
}

detail::CsvLine detail::CsvLine::of_part(const json& j) {
    const json& p = j.at("part");
    const auto t = j.at("time_ns").get<std::int64_t>();
    CsvLine c;
    c.recipe = p.at("recipe").get<std::string>();
    c.header = kPartColumns;
    c.row = local_iso8601(t) + "," + utc_iso8601(t) + "," +
            std::to_string(j.at("sequence").get<std::uint64_t>()) + "," +
            cell(p.at("part_id").get<std::string>()) + "," + cell(c.recipe) + "," +
            number(number_in(p.at("temperature_c")), 1) + "," + p.at("verdict").get<std::string>() +
            "," + (p.at("degraded").get<bool>() ? "yes" : "no");
    std::string drifting;  // "Diameter 3 DRIFT_UP; …": the features the watch warns of
    const json& drift = j.at("drift");
    for (const auto& f : p.at("features")) {
        const auto name = f.at("name").get<std::string>();
        if (const auto d = drift.find(name); d != drift.end() && text_in(*d).rfind("DRIFT", 0) == 0)
            drifting += (drifting.empty() ? "" : "; ") + name + " " + text_in(*d);
    }
    c.row += "," + cell(drifting) + "," +
             (j.contains("remeasure_of") && j["remeasure_of"].is_number_unsigned()
                  ? std::to_string(j["remeasure_of"].get<std::uint64_t>())
                  : "");
    for (const auto& f : p.at("features")) {
        const auto name = f.at("name").get<std::string>();
        for (const char* column : {" value_mm", " deviation_mm", " verdict", " nominal_mm",
                                   " lower_limit_mm", " upper_limit_mm", " reason"})
            c.header += "," + cell(name + column);
        // The value a quality engineer compares with the drawing: cold, in mm.
        const double nominal = f.at("nominal_mm").get<double>();
        const json& tol = f.at("tolerance_mm");
        c.row += "," + number(number_in(f.at("cold_mm")), 4) + "," +
                 number(number_in(f.at("deviation_mm")), 4) + "," +
                 f.at("verdict").get<std::string>() + "," + number(nominal, 4) + "," +
                 number(nominal + tol.at(0).get<double>(), 4) + "," +
                 number(nominal + tol.at(1).get<double>(), 4) + "," + cell(text_in(f.at("reason")));
    }
    return c;
}

detail::CsvLine detail::CsvLine::of_check(const json& j) {
    const json& v = j.at("verification");
    const json& p = j.at("part");
    CsvLine c;
    c.master = v.at("master").get<std::string>();
    c.header = "time,sequence,master,part_id,recipe,passed";
    c.row = local_iso8601(j.at("time_ns").get<std::int64_t>()) + "," +
            std::to_string(j.at("sequence").get<std::uint64_t>()) + "," + cell(*c.master) + "," +
            cell(p.at("part_id").get<std::string>()) + "," +
            cell(p.at("recipe").get<std::string>()) + "," +
            (v.at("passed").get<bool>() ? "yes" : "no");
    for (const auto& f : v.at("features")) {
        for (const char* column : {" certified_mm", " deviation_mm", " passed"})
            c.header += "," + cell(f.at("name").get<std::string>() + column);
        c.row += "," + number(number_in(f.at("certified_mm")), 4) + "," +
                 number(number_in(f.at("deviation_mm")), 4) + "," +
                 (f.at("passed").get<bool>() ? "yes" : "no");
    }
    return c;
}

std::string csv_row(const ResultEntry& e) { return detail::CsvLine::of(entry_json(e)).row; }
std::string verification_csv_row(const ResultEntry& e) { return csv_row(e); }
std::string jsonl_line(const ResultEntry& e) {
    return entry_json(e).dump();  // one line: no indentation, line breaks in strings escaped
}
std::string csv_row_of_line(const std::string& line) {
    return detail::CsvLine::of(json::parse(line)).row;
}

core::Result<ResultsLog> ResultsLog::open(const ResultsConfig& config) {
    std::error_code ec;
    std::filesystem::create_directories(config.dir, ec);
    if (ec)
        return core::make_error(config.dir.string() +
                                ": cannot create the results folder: " + ec.message());
    ResultsLog log(config);
    log.complete_csv();
    return log;
}

ResultsLog::ResultsLog(ResultsLog&& o) noexcept
    : config_(std::move(o.config_)),
      files_(std::move(o.files_)),
      last_csv_(std::move(o.last_csv_)),
      last_jsonl_(std::move(o.last_jsonl_)),
      last_line_(std::move(o.last_line_)),
      csv_error_(std::move(o.csv_error_)),
      owed_(std::move(o.owed_)),
      completed_(std::move(o.completed_)) {
    o.files_.clear();
}

ResultsLog& ResultsLog::operator=(ResultsLog&& o) noexcept {
    if (this != &o) {
        close_all();
        config_ = std::move(o.config_);
        files_ = std::move(o.files_);
        last_csv_ = std::move(o.last_csv_);
        last_jsonl_ = std::move(o.last_jsonl_);
        last_line_ = std::move(o.last_line_);
        csv_error_ = std::move(o.csv_error_);
        owed_ = std::move(o.owed_);
        completed_ = std::move(o.completed_);
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

// One line and its '\n', synced if asked. A write or a sync that fails is cut back to where the
// line started: a line is in the file whole, or not at all.
core::Result<void> ResultsLog::write_line(OpenFile& f, const std::filesystem::path& path,
                                          const std::string& line, bool sync) {
    const std::string data = line + "\n";
    struct stat st {};
    const off_t before = ::fstat(f.fd, &st) == 0 ? st.st_size : -1;
    auto cut_back = [&](int e, const char* what) -> core::Result<void> {
        if (before >= 0 && ::ftruncate(f.fd, before) != 0)
            log().error("{}: could not cut back a partial line: {}", path.string(),
                        errno_text(errno));
        return core::make_error(path.string() + ": " + what + errno_text(e));
    };
    std::size_t done = 0;
    while (done < data.size()) {
        const ssize_t n = ::write(f.fd, data.data() + done, data.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return cut_back(n < 0 ? errno : ENOSPC, "");
        done += static_cast<std::size_t>(n);
    }
    if (sync && config_.sync && ::fdatasync(f.fd) != 0)
        return cut_back(errno, "not stored durably: ");
    return {};
}

// The day's CSV file for a row: the day's first header keeps YYYY-MM-DD.csv (or
// .verification.csv); a part of another recipe goes to YYYY-MM-DD.<recipe>.csv, a master with
// other certified features to .verification.<master>.csv, and a header changed the same day (a
// recipe or certificate edited and reloaded) to a file named by its hash: never a row under
// another header's columns.
core::Result<std::filesystem::path> ResultsLog::csv_file(const detail::CsvLine& c) {
    const std::string base = c.date + (c.master ? ".verification" : "");
    std::filesystem::path csv = config_.dir / (base + ".csv");
    for (int attempt = 0;; ++attempt) {
        auto f = file(csv);
        if (!f) return f.error();
        if ((*f)->header.empty() || (*f)->header == c.header) return csv;
        if (attempt == 0) {
            csv =
                config_.dir / (base + "." + (c.master ? file_safe(*c.master) : c.recipe) + ".csv");
        } else if (attempt == 1) {
            char tag[17];
            std::snprintf(tag, sizeof tag, "%016zx", std::hash<std::string>{}(c.header));
            csv.replace_extension(std::string(tag).substr(0, 8) + ".csv");
        } else {
            return core::make_error(csv.string() + ": holds another header than this part's");
        }
    }
}

// The row (and the header, in a new file), not synced: the JSON line it comes from is.
core::Result<void> ResultsLog::write_csv(const detail::CsvLine& c) {
    auto csv = csv_file(c);
    if (!csv) return csv.error();
    OpenFile& f = files_.at(*csv);
    if (f.header.empty()) {
        if (auto ok = write_line(f, *csv, c.header, false); !ok) return ok;
        f.header = c.header;
    }
    if (auto ok = write_line(f, *csv, c.row, false); !ok) return ok;
    last_csv_ = *csv;
    return {};
}

// The rows of committed parts that a failed CSV write left owed, oldest first.
core::Result<void> ResultsLog::write_owed() {
    while (!owed_.empty()) {
        if (auto ok = write_csv(detail::CsvLine::of(nlohmann::json::parse(owed_.front()))); !ok)
            return ok;
        owed_.erase(owed_.begin());
    }
    return {};
}

void ResultsLog::sync_csv() {
    if (auto f = files_.find(last_csv_); config_.sync && f != files_.end())
        if (::fdatasync(f->second.fd) != 0)
            log().warn("{}: not synced: {}", last_csv_.string(), errno_text(errno));
}

core::Result<void> ResultsLog::append(const ResultEntry& e) {
    if (!e.result) return core::make_error("results: an entry without a result");
    const nlohmann::json j = entry_json(e);
    const detail::CsvLine c = detail::CsvLine::of(j);
    // The commit: the JSON line, synced. Everything else of the part follows from it.
    const std::filesystem::path jsonl = config_.dir / (c.date + ".jsonl");
    auto f = file(jsonl);
    if (!f) return f.error();
    std::string line = j.dump();  // one line: no indentation, line breaks in strings escaped
    if (auto ok = write_line(**f, jsonl, line, true); !ok) return ok;
    last_jsonl_ = jsonl;
    last_line_ = std::move(line);
    // The CSV row, derived: a failure leaves it owed (and said), the part committed.
    csv_error_.clear();
    auto ok = write_owed();
    if (ok) ok = write_csv(c);
    if (!ok) {
        owed_.push_back(last_line_);
        csv_error_ = ok.error().message;
        log().error(
            "seq {}: CSV row not written ({}); it is written from the JSON line before "
            "the next part's, or at the next start",
            e.sequence, csv_error_);
    }
    return {};
}

namespace {

// The sequence in a CSV file's last row: column 3 of a part's row ("time,time_utc,sequence"),
// column 2 of a master check's ("time,sequence", as its header begins); 0 when the file has only
// its header. (A last row with a quoted line break in it reads as 0: a part id or reason with a
// line break is not expected.)
std::uint64_t last_csv_sequence(const std::filesystem::path& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return 0;
    struct stat st {};
    char head[16] = {};
    const off_t end = ::fstat(fd, &st) == 0 ? line_end_before(fd, st.st_size) : -1;
    const off_t start = end > 0 ? line_end_before(fd, end - 1) : -1;
    std::string row(static_cast<std::size_t>(std::clamp<off_t>(end - 1 - start, 0, 256)), '\0');
    const bool read =
        start > 0 && ::pread(fd, head, sizeof head - 1, 0) > 0 &&
        ::pread(fd, row.data(), row.size(), start) == static_cast<ssize_t>(row.size());
    ::close(fd);
    if (!read) return 0;  // the header (or nothing)
    std::size_t at = 0;   // past the cells before the sequence (times: no comma, no quote)
    for (int cells = std::string_view(head).rfind("time,sequence,", 0) == 0 ? 1 : 2; cells > 0;
         --cells) {
        const auto comma = row.find(',', at);
        if (comma == std::string::npos) return 0;
        at = comma + 1;
    }
    std::uint64_t n = 0;
    std::from_chars(row.data() + at, row.data() + row.size(), n);
    return n;
}

// The highest sequence in the CSV files of one day (the day's, its recipes', its checks', those
// of an earlier header): a part is in the CSV when its sequence is not above it. (Rows are
// written in sequence order, whichever file they go to.)
std::uint64_t highest_csv_sequence(const std::filesystem::path& dir, const std::string& date) {
    std::uint64_t highest = 0;
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
        const std::string name = e.path().filename().string();
        if (name.rfind(date + ".", 0) == 0 && e.path().extension() == ".csv")
            highest = std::max(highest, last_csv_sequence(e.path()));
    }
    return highest;
}

}  // namespace

// After a crash between a part's JSON line and its CSV row, or a power cut before the unsynced
// CSV reached the disk: the rows of the last committed parts that the day's CSV files lack,
// written from the JSON lines, in order, then synced.
void ResultsLog::complete_csv() {
    std::map<std::string, std::uint64_t> in_csv;  // per local date: the highest sequence there
    std::set<std::filesystem::path> written;
    for (const auto& line : last_result_lines(config_.dir, kRecoverLines)) {
        std::optional<detail::CsvLine> c;
        try {
            c = detail::CsvLine::of(nlohmann::json::parse(line));
        } catch (const nlohmann::json::exception&) {
            continue;  // not a result line: read_parts names it
        }
        auto [it, fresh] = in_csv.try_emplace(c->date, 0);
        if (fresh) it->second = highest_csv_sequence(config_.dir, c->date);
        if (c->sequence <= it->second) continue;
        core::Result<void> ok;  // rows go in order: after one not written, the rest are owed
        if (owed_.empty()) ok = write_csv(*c);
        if (!ok || !owed_.empty()) {
            if (!ok) csv_error_ = ok.error().message;
            owed_.push_back(line);
            continue;
        }
        it->second = c->sequence;
        completed_.push_back(c->sequence);
        written.insert(last_csv_);
    }
    for (const auto& path : written)  // the files stay open unless more than 8 were touched
        if (auto f = files_.find(path); config_.sync && f != files_.end())
            ::fdatasync(f->second.fd);
    if (!completed_.empty())
        log().warn(
            "{}: wrote the CSV rows of sequences {}..{} ({} parts) from their JSON lines: "
            "the daemon had stopped before writing them",
            config_.dir.string(), completed_.front(), completed_.back(), completed_.size());
    if (!csv_error_.empty())
        log().error("{}: CSV rows owed from before: {}", config_.dir.string(), csv_error_);
}

std::vector<std::string> last_result_lines(const std::filesystem::path& dir, std::size_t max) {
    std::error_code ec;
    std::vector<std::filesystem::path> days;
    for (const auto& e : std::filesystem::directory_iterator(dir, ec))
        if (e.path().extension() == ".jsonl") days.push_back(e.path());
    std::sort(days.begin(), days.end());
    std::vector<std::string> out;  // newest first while reading
    const auto finish = [](std::vector<std::string>& lines) {
        std::reverse(lines.begin(), lines.end());
        return std::move(lines);
    };
    constexpr off_t kTail = 8 << 20;  // a line is 10–30 kB
    for (auto day = days.rbegin(); day != days.rend() && out.size() < max; ++day) {
        const int fd = ::open(day->c_str(), O_RDONLY | O_CLOEXEC);
        if (fd < 0) continue;
        struct stat st {};
        const off_t end = ::fstat(fd, &st) == 0 ? line_end_before(fd, st.st_size) : -1;
        const off_t from = std::max<off_t>(0, end - kTail);
        std::string tail(static_cast<std::size_t>(std::max<off_t>(0, end - from)), '\0');
        const bool read = end > 0 && ::pread(fd, tail.data(), tail.size(), from) ==
                                         static_cast<ssize_t>(tail.size());
        ::close(fd);
        if (!read) continue;
        std::size_t stop = tail.size() - 1;  // the '\n' ending the last whole line
        while (out.size() < max) {
            const std::size_t nl = stop == 0 ? std::string::npos : tail.rfind('\n', stop - 1);
            if (nl == std::string::npos && from > 0) return finish(out);  // no hole: stop
            const std::size_t begin = nl == std::string::npos ? 0 : nl + 1;
            if (stop > begin) out.push_back(tail.substr(begin, stop - begin));
            if (nl == std::string::npos) break;
            stop = nl;
        }
    }
    return finish(out);
}

}  // namespace hotgauge::results
