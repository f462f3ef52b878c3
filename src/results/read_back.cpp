#include "hotgauge/results/read_back.hpp"

#include <algorithm>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>

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

// The feature's value in one result line; nullopt when the part has no such feature.
std::optional<FeatureValue> value_of(const json& line, const std::string& feature) {
    const json& part = line.at("part");
    for (const json& f : part.at("features")) {
        if (f.at("name").get<std::string>() != feature) continue;
        FeatureValue v;
        v.sequence = line.at("sequence").get<std::uint64_t>();
        v.time = line.value("time", "");
        v.part_id = part.value("part_id", "");
        if (f.contains("cold_mm") && f["cold_mm"].is_number())
            v.cold_mm = f["cold_mm"].get<double>();
        v.verdict = f.value("verdict", "");
        return v;
    }
    return std::nullopt;
}

}  // namespace

core::Result<FeatureSeries> read_feature_values(const std::filesystem::path& dir,
                                                const std::string& feature) {
    const auto files = day_files(dir);
    if (!files) return files.error();
    FeatureSeries out;
    std::map<std::uint64_t, std::size_t> at;  // sequence → index in out.values
    for (const auto& path : *files) {
        std::ifstream in(path);
        if (!in) return core::make_error(path.string() + ": cannot open");
        ++out.files;
        std::string text;
        for (std::size_t n = 1; std::getline(in, text); ++n) {
            if (text.empty()) continue;
            ++out.lines;
            std::optional<FeatureValue> v;
            try {
                v = value_of(json::parse(text), feature);
            } catch (const json::exception& e) {
                return core::make_error(path.string() + ":" + std::to_string(n) +
                                        ": not a result line: " + e.what());
            }
            if (!v) {
                ++out.without_feature;
                continue;
            }
            if (auto seen = at.find(v->sequence); seen != at.end()) {
                out.values[seen->second] = std::move(*v);
                continue;
            }
            at[v->sequence] = out.values.size();
            out.values.push_back(std::move(*v));
        }
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
    if (!archived_as->is_string())
        return core::make_error(where + ": " + part +
                                " was not archived (the archive keeps NOK, degraded and "
                                "unmeasured parts and every Nth OK part)");
    std::filesystem::path folder = archived_as->get<std::string>();
    std::error_code ec;
    if (folder.is_relative() && !std::filesystem::exists(folder, ec)) folder = dir / folder;
    if (!std::filesystem::is_directory(folder, ec))
        return core::make_error(where + ": " + part + " was archived as " +
                                archived_as->get<std::string>() +
                                ", which is gone (deleted to keep the archive's quota?)");
    return folder;
}

}  // namespace hotgauge::results
