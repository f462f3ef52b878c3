#include "hotgauge/sim/simulator.hpp"

#include <chrono>
#include <cmath>
#include <ctime>
#include <numbers>
#include <random>

#include "hotgauge/core/clock.hpp"
#include "hotgauge/sim/scene.hpp"

namespace hotgauge::sim {
namespace {

constexpr double kG = 9.81;  // m/s², as recording-format-v1 defines g_up
constexpr double kNsPerS = 1e9;
constexpr double kDeg = std::numbers::pi / 180.0;

}  // namespace

CellConfig quick(CellConfig cell) {
    cell.sensor.width /= 4;
    cell.sensor.pitch_mm *= 4.0;
    for (auto& f : cell.faces) f.profile_spacing_mm = std::max(f.profile_spacing_mm, 1.0);
    cell.accel.rate_hz = std::min(cell.accel.rate_hz, 1000.0);
    return cell;
}

core::Result<SimResult> simulate(const core::Recipe& recipe, const CellConfig& cell,
                                 const SimOptions& opt) {
    if (cell.faces.empty()) return core::make_error("cell config: no faces to scan");
    if (cell.sensor.width < 2) return core::make_error("cell config: sensor.width must be >= 2");
    std::vector<const FaceConfig*> faces;
    for (const auto& f : cell.faces)
        if (opt.faces.empty() ||
            std::find(opt.faces.begin(), opt.faces.end(), f.name) != opt.faces.end())
            faces.push_back(&f);
    if (faces.size() != (opt.faces.empty() ? cell.faces.size() : opt.faces.size()))
        return core::make_error("simulate: a requested face is not in the cell config");

    std::mt19937_64 rng(opt.seed);
    auto scene = Scene::create(recipe, cell, opt, rng);
    if (!scene) return scene.error();
    SimResult out;
    SimTruth& truth = out.truth;
    truth = scene->truth();

    // Timeline: face j is scanned after face j−1 plus the robot's move; accelerometer margins.
    const auto& s = cell.sensor;
    std::vector<double> t_start(faces.size());
    std::vector<std::int64_t> n_prof(faces.size());
    double t = cell.accel.margin_s;
    for (std::size_t j = 0; j < faces.size(); ++j) {
        n_prof[j] = static_cast<std::int64_t>(
                        std::floor(faces[j]->scan_length_mm / faces[j]->profile_spacing_mm)) +
                    1;
        t_start[j] = t;
        t += static_cast<double>(n_prof[j]) / s.line_rate_hz + cell.face_gap_s;
    }
    const double t_end = t + cell.accel.margin_s;
    // Everything of this scan (vibration, sensor noise, accelerometer) from its own stream, so
    // the same part can be scanned again under other vibration (scan_seed).
    RandomStream scan_rng(opt.scan_seed ? *opt.scan_seed : rng());
    const Vibration vib(cell.vibration, 0.0, t_end, scan_rng.engine);

    const std::int64_t t0_ns = opt.t0_ns ? opt.t0_ns : core::realtime_ns();
    core::Recording& rec = out.recording;
    rec.part_id = opt.part_id;
    rec.recipe = recipe.name;
    rec.captured_at = opt.captured_at.empty() ? core::iso8601_utc(t0_ns) : opt.captured_at;
    rec.temperature_c = opt.temperature_c;

    std::vector<RayReturn> returns;
    for (std::size_t j = 0; j < faces.size(); ++j) {
        const FaceConfig& fc = *faces[j];
        core::FaceScan face;
        FaceTruth ft;
        face.name = ft.name = fc.name;
        face.T_world_camera = fc.T_world_camera;
        face.scan_direction = fc.scan_direction;
        face.R_camera_accel = fc.R_camera_accel;
        face.width = s.width;
        const std::int64_t n = n_prof[j];
        face.profiles_mm.assign(static_cast<std::size_t>(n * s.width * 2),
                                std::numeric_limits<float>::quiet_NaN());
        ft.spike.assign(static_cast<std::size_t>(n * s.width), 0);
        const Eigen::Matrix3d R = fc.T_world_camera.linear();
        for (std::int64_t k = 0; k < n; ++k) {
            const double tk = t_start[j] + static_cast<double>(k) / s.line_rate_hz;
            const double pos = static_cast<double>(k) * fc.profile_spacing_mm;
            face.profile_times_ns.push_back(t0_ns + std::llround(tk * kNsPerS));
            face.profile_positions_mm.push_back(pos);
            const Eigen::Vector3d u = vib.displacement_mm(tk);
            ft.u_mm.push_back(u);
            // True sensor pose: nominal + scan travel + vibration (translation only).
            const Eigen::Vector3d origin =
                fc.T_world_camera.translation() + pos * fc.scan_direction + u;
            scene->cast_profile(fc, origin, scan_rng, returns);
            for (int i = 0; i < s.width; ++i) {
                const RayReturn& r = returns[i];
                if (std::isnan(r.x_mm)) continue;
                face.profiles_mm[(k * s.width + i) * 2] = r.x_mm;
                face.profiles_mm[(k * s.width + i) * 2 + 1] = r.z_mm;
                if (r.spike) {
                    ft.spike[k * s.width + i] = 1;
                    ++ft.n_spikes;
                }
            }
        }

        // Accelerometer in the head: a_acc = R_accᵀ·(ü/1000 + g_up) + bias + noise, clipped.
        const auto& a = cell.accel;
        const AccelHead head(a, R * fc.R_camera_accel, scan_rng);
        const double ta = t_start[j] - a.margin_s;
        const double tb = t_start[j] + static_cast<double>(n - 1) / s.line_rate_hz + a.margin_s;
        const auto n_acc = static_cast<std::int64_t>(std::floor((tb - ta) * a.rate_hz)) + 1;
        std::int64_t last_ns = std::numeric_limits<std::int64_t>::min();
        for (std::int64_t q = 0; q < n_acc; ++q) {
            double tq = ta + static_cast<double>(q) / a.rate_hz;
            if (a.jitter_ns > 0) tq += a.jitter_ns * 1e-9 * (2 * scan_rng.uniform() - 1);
            const std::int64_t tq_ns = t0_ns + std::llround(tq * kNsPerS);
            if (tq_ns <= last_ns) continue;
            last_ns = tq_ns;
            const Eigen::Vector3f acc = head.sample(vib, tq, scan_rng);
            face.accel_mps2.insert(face.accel_mps2.end(), acc.data(), acc.data() + 3);
            face.accel_times_ns.push_back(tq_ns);
        }
        rec.faces.push_back(std::move(face));
        truth.faces.push_back(std::move(ft));
    }
    return out;
}

}  // namespace hotgauge::sim
