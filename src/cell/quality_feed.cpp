#include "hotgauge/cell/quality_feed.hpp"

#include <spdlog/spdlog.h>

#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>

#include "hotgauge/report/lot_report.hpp"
#include "hotgauge/results/results_log.hpp"

namespace hotgauge::cell {
namespace {

// The last `days` day files' first day (YYYY-MM-DD), as a range bound.
std::string first_of_last_days(const std::filesystem::path& dir, std::size_t days) {
    std::vector<std::string> names;
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(dir, ec))
        if (e.path().extension() == ".jsonl") names.push_back(e.path().stem().string());
    std::sort(names.begin(), names.end());
    return names.size() > days ? names[names.size() - days] : "";
}

using nlohmann::json;

json to_json(const quality::DriftWatch::Saved& s) {
    json j = {{"die", s.die}, {"recipe", s.recipe}, {"feature", s.feature}};
    if (s.watching) {
        j["mean"] = s.mean, j["sigma"] = s.sigma, j["z"] = s.z, j["n"] = s.n;
    } else {
        j["baseline"] = s.baseline;
    }
    return j;
}

quality::DriftWatch::Saved saved_of(const json& j) {
    quality::DriftWatch::Saved s;
    s.die = j.at("die").get<int>();
    s.recipe = j.at("recipe").get<std::string>();
    s.feature = j.at("feature").get<std::string>();
    s.watching = j.contains("mean");
    if (s.watching) {
        s.mean = j.at("mean").get<double>();
        s.sigma = j.at("sigma").get<double>();
        s.z = j.at("z").get<double>();
        s.n = j.at("n").get<std::size_t>();
    } else {
        s.baseline = j.at("baseline").get<std::vector<double>>();
    }
    return s;
}

// Text to a file through a temporary one and a rename: a reader sees the old or the new.
bool replace_file(const std::filesystem::path& path, const std::string& text) {
    const auto tmp = path.string() + ".tmp";
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        out << text;
        if (!out.flush()) {
            spdlog::error("quality: {}: cannot write", tmp);
            return false;
        }
    }
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);
    if (ec) spdlog::error("quality: {}: {}", path.string(), ec.message());
    return !ec;
}

}  // namespace

QualityFeed::QualityFeed(const std::filesystem::path& results_dir, const QualityConfig& config)
    : dir_(results_dir), config_(config) {
    if (config_.drift_baseline > 0)
        watch_.emplace(quality::DriftWatchConfig{config_.drift_baseline});
}

QualityFeed::~QualityFeed() {
    if (unwritten_) write_report();
}

bool QualityFeed::restore_watch() {
    const auto path = dir_ / "drift-watch.json";
    std::ifstream in(path);
    if (!in) return false;
    try {
        const json j = json::parse(in);
        for (const json& s : j.at("series")) watch_->restore(saved_of(s));
        spdlog::info("quality: drift watch of {} series from {}", j.at("series").size(),
                     path.string());
        return true;
    } catch (const json::exception& e) {  // rebuilt from the results files instead
        spdlog::warn("quality: {}: {}; the drift watch is rebuilt from the results files",
                     path.string(), e.what());
        watch_.emplace(quality::DriftWatchConfig{config_.drift_baseline});
        return false;
    }
}

void QualityFeed::save_watch() const {
    json series = json::array();
    for (const auto& s : watch_->saved()) series.push_back(to_json(s));
    replace_file(dir_ / "drift-watch.json", json{{"series", series}}.dump() + "\n");
}

void QualityFeed::load(std::int64_t now_ns) {
    today_ = results::local_date(now_ns);
    parts_.clear();
    // The watch as it was after the last part; without that file (the first start), rebuilt
    // from the last 3 days of results.
    const bool restored = watch_ && restore_watch();
    const results::TimeRange range{restored ? today_ : first_of_last_days(dir_, 3), ""};
    const auto read = results::read_parts(dir_, range, true);
    if (!read) {  // a new cell has no results yet: nothing to go on from
        spdlog::info("quality: {}: starting without earlier results", read.error().message);
        return;
    }
    for (const auto& why : read->skipped) spdlog::warn("quality: skipped {}", why);
    for (const auto& p : read->parts) {
        if (watch_ && !restored && !p.master_check)  // masters are no production
            for (const auto& f : p.features) watch_->add(p.die, p.recipe, f.name, f.usable_mm());
        if (p.time.compare(0, today_.size(), today_) == 0) parts_.push_back(p);
    }
    spdlog::info("quality: {} results read from {} day files{}; today's report has {} parts",
                 read->parts.size(), read->files,
                 watch_ && !restored ? " (the drift watch rebuilt from them)" : "", parts_.size());
}

std::vector<std::pair<std::string, std::string>> QualityFeed::observe(
    int die, const pipeline::PartResult& r) {
    std::vector<std::pair<std::string, std::string>> out;
    if (!watch_) return out;
    for (const auto& f : r.measurement.features) {
        const bool used = f.verdict == measure::Verdict::kOk || f.verdict == measure::Verdict::kNok;
        const auto state = watch_->add(die, r.recipe, f.name, used ? f.cold_mm : std::nullopt);
        out.emplace_back(f.name, quality::to_string(state));
    }
    save_watch();
    return out;
}

void QualityFeed::stored(const std::string& jsonl_line, std::int64_t time_ns) {
    if (!config_.lot_report) return;
    const std::string day = results::local_date(time_ns);
    if (day != today_) {
        if (unwritten_) write_report();  // the day's last parts
        today_ = day;
        parts_.clear();
    }
    try {
        parts_.push_back(results::parse_result_line(jsonl_line));
    } catch (const nlohmann::json::exception& e) {
        spdlog::error("lot report: the results line does not read back: {}", e.what());
        return;
    }
    unwritten_ = true;
    if (!written_ ||
        std::chrono::duration<double>(std::chrono::steady_clock::now() - *written_).count() >=
            config_.lot_report_every_s)
        write_report();
}

void QualityFeed::write_report() {
    unwritten_ = false;
    written_ = std::chrono::steady_clock::now();
    const auto t0 = std::chrono::steady_clock::now();
    report::LotOptions options;
    options.title = "Lot report " + today_ + " (hotgauged, updated as parts come)";
    const std::string html =
        report::lot_report_html(report::summarize_lot(parts_, options), options);
    if (!replace_file(dir_ / (today_ + ".report.html"), html)) return;
    spdlog::debug(
        "lot report: {} parts, {} ms", parts_.size(),
        std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - t0)
            .count());
}

}  // namespace hotgauge::cell
