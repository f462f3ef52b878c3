// hotgauge fit plane|circle|circle3d FILE: one least-squares fit of a point file, printed as one
// JSON object (docs/fitting.md). Reads `x y` / `x y z` per line (`#` comments, blank lines) and
// the NIST .ds layout (a first line with the point count).
#include <spdlog/spdlog.h>

#include <charconv>
#include <cmath>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "commands.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/measure/fit.hpp"

namespace hotgauge::app {
namespace {

struct FitArgs {
    std::string type;
    std::string file;
};

std::vector<std::string_view> split(std::string_view line) {
    std::vector<std::string_view> tokens;
    std::size_t i = 0;
    while (i < line.size()) {
        while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
        const std::size_t start = i;
        while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
        if (i > start) tokens.push_back(line.substr(start, i - start));
    }
    return tokens;
}

bool parse_double(std::string_view s, double& out) {
    if (!s.empty() && s.front() == '+') s.remove_prefix(1);
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
    return ec == std::errc() && end == s.data() + s.size() && std::isfinite(out);
}

// A non-negative integer that fills the token: the NIST .ds point count.
bool parse_count(std::string_view s, long long& out) {
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
    return ec == std::errc() && end == s.data() + s.size() && out >= 0;
}

// Rows of `dims` finite numbers. A first data line holding a single integer is the NIST .ds point
// count, and the number of rows must match it.
core::Result<std::vector<Eigen::Vector3d>> read_points(const std::string& path, int dims) {
    std::ifstream in(path);
    if (!in) return core::make_error(path + ": cannot open");
    std::vector<Eigen::Vector3d> rows;
    std::string line;
    long long expected = -1;
    bool first = true;
    for (int line_no = 1; std::getline(in, line); ++line_no) {
        std::string_view content(line);
        if (const auto hash = content.find('#'); hash != std::string_view::npos)
            content = content.substr(0, hash);
        const auto tokens = split(content);
        if (tokens.empty()) continue;
        const std::string where = path + ":" + std::to_string(line_no) + ": ";
        if (long long count = 0; first && tokens.size() == 1 && parse_count(tokens[0], count)) {
            first = false;
            expected = count;
            continue;
        }
        first = false;
        if (static_cast<int>(tokens.size()) != dims)
            return core::make_error(where + "expected " + std::to_string(dims) + " numbers (" +
                                    (dims == 2 ? "x y" : "x y z") + "), found " +
                                    std::to_string(tokens.size()));
        Eigen::Vector3d p = Eigen::Vector3d::Zero();
        for (int k = 0; k < dims; ++k)
            if (!parse_double(tokens[k], p[k]))
                return core::make_error(where + "not a finite number: '" + std::string(tokens[k]) +
                                        "'");
        rows.push_back(p);
    }
    if (in.bad()) return core::make_error(path + ": read error");
    if (expected >= 0 && expected != static_cast<long long>(rows.size()))
        return core::make_error(path + ": header says " + std::to_string(expected) +
                                " points, found " + std::to_string(rows.size()));
    return rows;
}

using Json = nlohmann::ordered_json;  // keys in the documented order

core::Result<Json> fit(const std::string& type, const std::vector<Eigen::Vector3d>& pts) {
    Json j;
    j["type"] = type;
    if (type == "plane") {
        auto f = measure::fit_plane(pts);
        if (!f) return f.error();
        j["point"] = {f->point.x(), f->point.y(), f->point.z()};
        j["normal"] = {f->normal.x(), f->normal.y(), f->normal.z()};
        j["rms"] = f->rms_mm;
        j["n_points"] = f->n_points;
    } else if (type == "circle") {
        std::vector<Eigen::Vector2d> p2;
        p2.reserve(pts.size());
        for (const auto& p : pts) p2.push_back(p.head<2>());
        auto f = measure::fit_circle(p2);
        if (!f) return f.error();
        j["center"] = {f->center.x(), f->center.y()};
        j["radius"] = f->radius;
        j["rms"] = f->rms_mm;
        j["n_points"] = f->n_points;
    } else {
        auto f = measure::fit_circle3d(pts);
        if (!f) return f.error();
        j["center"] = {f->center.x(), f->center.y(), f->center.z()};
        j["axis"] = {f->axis.x(), f->axis.y(), f->axis.z()};
        j["radius"] = f->radius;
        j["rms"] = f->rms_mm;
        j["n_points"] = f->n_points;
    }
    return j;
}

int run(const FitArgs& a) {
    auto pts = read_points(a.file, a.type == "circle" ? 2 : 3);
    if (!pts) {
        spdlog::error("{}", pts.error().message);
        return 1;
    }
    auto j = fit(a.type, *pts);
    if (!j) {
        spdlog::error("{}: {}", a.file, j.error().message);
        return 1;
    }
    // dump() prints the shortest decimal that round-trips each double.
    std::cout << j->dump() << '\n';
    return 0;
}

}  // namespace

Command add_fit(CLI::App& app) {
    auto a = std::make_shared<FitArgs>();
    auto* s = app.add_subcommand("fit", "least-squares plane or circle of a point file, as JSON");
    s->add_option("type", a->type, "plane | circle (x y) | circle3d (x y z)")
        ->required()
        ->check(CLI::IsMember({"plane", "circle", "circle3d"}));
    s->add_option("file", a->file, "points, one per line; '#' comments; NIST .ds accepted")
        ->required();
    return [a] { return run(*a); };
}

}  // namespace hotgauge::app
