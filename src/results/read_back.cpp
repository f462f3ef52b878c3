#include "hotgauge/results/read_back.hpp"

#include <algorithm>
#include <array>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string_view>

#include "hotgauge/io/bytes.hpp"
#include "hotgauge/results/archive.hpp"

namespace hotgauge::results {
namespace {

using nlohmann::json;

core::Result<std::vector<std::filesystem::path>> day_files(const std::filesystem::path& dir) {
    std::error_code ec;
    std::vector<std::filesystem::path> files;
    std::filesystem::directory_iterator it(dir, ec), end;
    if (ec)
        return core::make_error(dir.string() + ": cannot read the results folder: " + ec.message());
    for (; it != end; it.increment(ec)) {
        if (ec) return core::make_error(dir.string() + ": " + ec.message());
        if (it->path().extension() == ".jsonl") files.push_back(it->path());
    }
    if (files.empty()) return core::make_error(dir.string() + ": no results (*.jsonl) in it");
    std::sort(files.begin(), files.end());
    return files;
}

// The parts of a line a reader of values needs; the rest (per-face, compensation, matching,
// uncertainty budgets: most of a line's bytes) is skipped while parsing.
bool keep(int /*depth*/, json::parse_event_t event, json& parsed) {
    static constexpr std::array<std::string_view, 9> kSkipped = {
        "compensation", "faces", "match",    "stage_ms", "u_budget_mm",
        "edge",         "ends",  "left_out", "warnings"};
    if (event != json::parse_event_t::key) return true;
    const auto& key = parsed.get_ref<const std::string&>();
    return std::find(kSkipped.begin(), kSkipped.end(), key) == kSkipped.end();
}

std::optional<double> number_or_null(const json& j, const char* key) {
    if (auto it = j.find(key); it != j.end() && it->is_number()) return it->get<double>();
    return std::nullopt;
}

FeatureRecord feature_of(const json& f) {
    FeatureRecord r;
    r.name = f.at("name").get<std::string>();
    r.slot = f.value("slot", 0);
    r.nominal_mm = f.at("nominal_mm").get<double>();
    const json& tol = f.at("tolerance_mm");
    r.lower_mm = tol.at(0).get<double>();
    r.upper_mm = tol.at(1).get<double>();
    r.cold_mm = number_or_null(f, "cold_mm");
    r.u_cold_mm = number_or_null(f, "u_cold_mm");
    r.verdict = f.value("verdict", "");
    if (auto it = f.find("reason"); it != f.end() && it->is_string()) r.reason = *it;
    return r;
}

PartRecord part_of(const json& line) {
    PartRecord p;
    p.sequence = line.at("sequence").get<std::uint64_t>();
    p.time_ns = line.value("time_ns", std::int64_t{0});
    p.time = line.value("time", "");
    p.master_check = line.contains("verification");
    p.die = line.value("die", 0);
    if (auto v = line.find("verification"); v != line.end()) {
        p.master = v->value("master", "");
        for (const json& f : v->at("features"))
            p.certified.emplace_back(f.at("name").get<std::string>(),
                                     f.at("certified_mm").get<double>());
    }
    if (auto a = line.find("archived_as"); a != line.end() && a->is_string())
        p.archived_as = a->get<std::string>();
    const json& part = line.at("part");
    p.part_id = part.value("part_id", "");
    p.recipe = part.value("recipe", "");
    p.verdict = part.value("verdict", "");
    p.temperature_c = number_or_null(part, "temperature_c");
    for (const json& f : part.at("features")) p.features.push_back(feature_of(f));
    return p;
}

// "2026-12-04.jsonl" can hold parts in the range only if its day can.
bool day_may_hold(const std::filesystem::path& file, const TimeRange& range) {
    const std::string day = file.stem().string();
    if (!range.from.empty() && day < range.from.substr(0, day.size())) return false;
    if (!range.to.empty() && day > range.to.substr(0, day.size())) return false;
    return true;
}

// The lines of one day file's text into `out`, a sequence seen before replacing its part.
core::Result<void> read_lines(std::string_view text, const std::filesystem::path& path,
                              const TimeRange& range, bool skip_bad_lines, PartsRead& out,
                              std::map<std::uint64_t, std::size_t>& at) {
    ++out.files;
    for (std::size_t n = 1; !text.empty(); ++n) {
        const std::size_t end = std::min(text.find('\n'), text.size());
        const std::string_view line = text.substr(0, end);
        text.remove_prefix(std::min(end + 1, text.size()));
        if (line.empty()) continue;
        ++out.lines;
        PartRecord p;
        try {
            p = parse_result_line(line);
        } catch (const json::exception& e) {
            std::string why =
                path.string() + ":" + std::to_string(n) + ": not a result line: " + e.what();
            if (!skip_bad_lines) return core::make_error(std::move(why));
            out.skipped.push_back(std::move(why));
            continue;
        }
        if (!range.contains(p.time)) continue;
        if (auto seen = at.find(p.sequence); seen != at.end()) {
            out.parts[seen->second] = std::move(p);
            continue;
        }
        at[p.sequence] = out.parts.size();
        out.parts.push_back(std::move(p));
    }
    return {};
}

}  // namespace

PartRecord parse_result_line(std::string_view line) { return part_of(json::parse(line, keep)); }

bool TimeRange::contains(const std::string& time) const {
    if (!from.empty() && time.compare(0, from.size(), from) < 0) return false;
    if (!to.empty() && time.compare(0, to.size(), to) > 0) return false;
    return true;
}

core::Result<PartsRead> read_parts(const std::filesystem::path& dir, const TimeRange& range,
                                   bool skip_bad_lines) {
    const auto files = day_files(dir);
    if (!files) return files.error();
    PartsRead out;
    std::map<std::uint64_t, std::size_t> at;  // sequence → index in out.parts
    for (const auto& path : *files) {
        if (!day_may_hold(path, range)) continue;
        auto bytes = io::read_bytes(path);
        if (!bytes) return bytes.error();
        if (auto ok = read_lines(bytes->text(), path, range, skip_bad_lines, out, at); !ok)
            return ok.error();
    }
    return out;
}

core::Result<PartsRead> parse_parts(std::string_view text, const std::filesystem::path& file,
                                    const TimeRange& range, bool skip_bad_lines) {
    PartsRead out;
    std::map<std::uint64_t, std::size_t> at;
    if (auto ok = read_lines(text, file, range, skip_bad_lines, out, at); !ok) return ok.error();
    return out;
}

core::Result<FeatureSeries> read_feature_values(const std::filesystem::path& dir,
                                                const std::string& feature) {
    const auto read = read_parts(dir);
    if (!read) return read.error();
    FeatureSeries out;
    out.files = read->files;
    out.lines = read->lines;
    for (const PartRecord& p : read->parts) {
        const auto f = std::find_if(p.features.begin(), p.features.end(),
                                    [&](const FeatureRecord& r) { return r.name == feature; });
        if (f == p.features.end()) {
            ++out.without_feature;
            continue;
        }
        out.values.push_back({p.sequence, p.time, p.part_id, f->cold_mm, f->verdict});
    }
    if (out.values.empty())
        return core::make_error(dir.string() + ": no part has a feature '" + feature + "' (" +
                                std::to_string(out.lines) + " results read)");
    return out;
}

core::Result<std::filesystem::path> archived_recording(const std::filesystem::path& dir,
                                                       std::uint64_t sequence) {
    const auto files = day_files(dir);
    if (!files) return files.error();
    std::optional<json> archived_as;  // of the last line with the sequence
    std::string where;                // that line's file:line
    for (const auto& path : *files) {
        std::ifstream in(path);
        if (!in) return core::make_error(path.string() + ": cannot open");
        std::string text;
        for (std::size_t n = 1; std::getline(in, text); ++n) {
            if (text.empty()) continue;
            try {
                const json line = json::parse(text);
                if (line.at("sequence").get<std::uint64_t>() != sequence) continue;
                archived_as = line.value("archived_as", json());
            } catch (const json::exception& e) {
                return core::make_error(path.string() + ":" + std::to_string(n) +
                                        ": not a result line: " + e.what());
            }
            where = path.string() + ":" + std::to_string(n);
        }
    }
    const std::string part = "part sequence " + std::to_string(sequence);
    if (!archived_as)
        return core::make_error(dir.string() + ": no " + part + " in the results (" +
                                std::to_string(files->size()) + " day files)");
    PartRecord record;
    record.sequence = sequence;
    if (archived_as->is_string()) record.archived_as = archived_as->get<std::string>();
    return archived_folder(dir, record, where);
}

core::Result<std::filesystem::path> archived_folder(const std::filesystem::path& dir,
                                                    const PartRecord& record,
                                                    const std::string& where) {
    const std::string part = "part sequence " + std::to_string(record.sequence);
    if (!record.archived_as)
        return core::make_error(where + ": " + part +
                                " was not archived (the archive keeps NOK, degraded and "
                                "unmeasured parts and every Nth OK part)");
    std::filesystem::path folder = *record.archived_as;
    std::error_code ec;
    if (folder.is_relative() && !std::filesystem::exists(folder, ec)) folder = dir / folder;
    if (!std::filesystem::is_directory(folder, ec))
        return core::make_error(where + ": " + part + " was archived as " + *record.archived_as +
                                ", which is gone (deleted to keep the archive's quota?)");
    if (std::ifstream note(folder / RawArchive::kNotArchived); note) {
        std::string why;
        std::getline(note, why);
        return core::make_error(where + ": " + part + " has no recording in " + folder.string() +
                                ": " + why);
    }
    return folder;
}

}  // namespace hotgauge::results
