// hotgauge measure: the offline pipeline on a recording. Today: nominal world cloud per face and
// a per-face acquisition summary; the measuring stages plug in here (docs/architecture.md).
#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>

#include "commands.hpp"
#include "hotgauge/core/geometry.hpp"
#include "hotgauge/io/ply.hpp"
#include "hotgauge/io/recording_io.hpp"

namespace hotgauge::app {
namespace {

struct MeasureArgs {
    std::string recording;
    std::string ply;
};

// What was acquired on one face: enough for an engineer to judge the data before the numbers.
struct FaceSummary {
    std::int64_t profiles = 0, width = 0, points = 0;
    double nan_fraction = 0;
    double scan_s = 0;
    std::int64_t accel_samples = 0;
    double accel_rate_hz = 0;
    double margin_before_s = NAN, margin_after_s = NAN;
};

FaceSummary summarize(const core::FaceScan& f, std::int64_t points) {
    FaceSummary s;
    s.profiles = f.n_profiles();
    s.width = f.width;
    s.points = points;
    const double total = static_cast<double>(s.profiles * s.width);
    s.nan_fraction = total > 0 ? 1.0 - static_cast<double>(points) / total : 0.0;
    if (s.profiles > 1)
        s.scan_s =
            static_cast<double>(f.profile_times_ns.back() - f.profile_times_ns.front()) * 1e-9;
    s.accel_samples = f.n_accel();
    if (s.accel_samples > 1) {
        const double span =
            static_cast<double>(f.accel_times_ns.back() - f.accel_times_ns.front()) * 1e-9;
        s.accel_rate_hz = static_cast<double>(s.accel_samples - 1) / span;
        if (s.profiles > 0) {
            s.margin_before_s =
                static_cast<double>(f.profile_times_ns.front() - f.accel_times_ns.front()) * 1e-9;
            s.margin_after_s =
                static_cast<double>(f.accel_times_ns.back() - f.profile_times_ns.back()) * 1e-9;
        }
    }
    return s;
}

int run(const MeasureArgs& a) {
    auto rec = io::read_recording(a.recording);
    if (!rec) {
        spdlog::error("{}", rec.error().message);
        return 1;
    }
    for (const auto& w : rec->warnings) spdlog::warn("{}", w);
    std::printf(
        "part %s  recipe %s  captured %s  temperature %s\n", rec->part_id.c_str(),
        rec->recipe.c_str(), rec->captured_at.c_str(),
        rec->temperature_c ? (std::to_string(*rec->temperature_c) + " °C").c_str() : "unknown");
    std::printf("%-8s %8s %6s %10s %6s %8s %8s %8s %9s %9s\n", "face", "profiles", "width",
                "points", "NaN %", "scan s", "accel", "accel Hz", "before s", "after s");
    std::vector<Eigen::Vector3d> all;
    for (const auto& f : rec->faces) {
        auto cloud = core::world_cloud(f);
        const FaceSummary s = summarize(f, static_cast<std::int64_t>(cloud.points_mm.size()));
        std::printf("%-8s %8lld %6lld %10lld %6.2f %8.3f %8lld %8.1f %9.3f %9.3f\n", f.name.c_str(),
                    static_cast<long long>(s.profiles), static_cast<long long>(s.width),
                    static_cast<long long>(s.points), 100.0 * s.nan_fraction, s.scan_s,
                    static_cast<long long>(s.accel_samples), s.accel_rate_hz, s.margin_before_s,
                    s.margin_after_s);
        if (!a.ply.empty()) all.insert(all.end(), cloud.points_mm.begin(), cloud.points_mm.end());
    }
    if (!a.ply.empty()) {
        if (auto r = io::write_ply(a.ply, all); !r) {
            spdlog::error("{}", r.error().message);
            return 1;
        }
        spdlog::info("wrote {} world points (nominal, uncompensated) to {}", all.size(), a.ply);
    }
    return 0;
}

}  // namespace

Command add_measure(CLI::App& app) {
    auto a = std::make_shared<MeasureArgs>();
    auto* s = app.add_subcommand("measure", "measure a recording (offline pipeline)");
    s->add_option("recording", a->recording, "recording folder (hotgauge-recording/1)")->required();
    s->add_option("--ply", a->ply, "write the world cloud of all faces as binary PLY");
    return [a] { return run(*a); };
}

}  // namespace hotgauge::app
