#include "hotgauge/sim/simulator.hpp"

#include <chrono>
#include <cmath>
#include <ctime>
#include <numbers>
#include <random>

namespace hotgauge::sim {
namespace {

constexpr double kG = 9.81;  // m/s², as recording-format-v1 defines g_up
constexpr double kNsPerS = 1e9;
constexpr double kDeg = std::numbers::pi / 180.0;

std::string iso8601_utc(std::int64_t ns) {
    const std::time_t secs = static_cast<std::time_t>(ns / 1'000'000'000);
    std::tm tm{};
    gmtime_r(&secs, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return buf;
}

// Random as-forged part: every level (but the origin level) and diameter off nominal by N(0, σ).
void draw_dimensions(const core::Recipe& recipe, double sigma, std::mt19937_64& rng,
                     SimTruth& truth) {
    std::normal_distribution<double> dev(0.0, sigma);
    for (std::size_t i = 0; i < recipe.levels_mm.size(); ++i) {
        const auto& [name, z] = recipe.levels_mm[i];
        truth.levels_mm[name] = z == 0.0 ? 0.0 : z + dev(rng);
    }
    for (const auto* list : {&recipe.outer, &recipe.inner})
        for (const auto& s : *list) truth.diameters_mm[s.name] = s.diameter_mm + dev(rng);
    for (const auto& f : recipe.features) {
        const double cold =
            f.kind == core::FeatureKind::kDiameter
                ? truth.diameters_mm.at(f.section)
                : std::abs(truth.levels_mm.at(f.to_level) - truth.levels_mm.at(f.from_level));
        truth.features.push_back({f.name, cold * truth.growth, cold});
    }
}

Eigen::Isometry3d random_placement(const CellConfig& cell, double bottom_radius_mm,
                                   std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    const double yaw = 2.0 * std::numbers::pi * u01(rng);
    const double tilt = cell.placement.max_tilt_deg * kDeg * u01(rng);
    const double tilt_dir = 2.0 * std::numbers::pi * u01(rng);
    const double m = cell.placement.max_offset_mm;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.rotate(Eigen::AngleAxisd(tilt, Eigen::Vector3d(std::cos(tilt_dir), std::sin(tilt_dir), 0)));
    T.rotate(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
    // Tilted on pins: lift so the lowest rim point just clears the support.
    T.translation() = Eigen::Vector3d(m * (2 * u01(rng) - 1), m * (2 * u01(rng) - 1),
                                      bottom_radius_mm * std::sin(tilt));
    return T;
}

struct RayHit {
    double t;
    Eigen::Vector3d normal;
};

// First hit of a world ray on the part or (when visible) the support plate.
std::optional<RayHit> cast(const core::AxisymmetricSolid& solid,
                           const Eigen::Isometry3d& T_part_world, bool support, double support_half,
                           const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_max) {
    std::optional<RayHit> best;
    const Eigen::Vector3d op = T_part_world * o, dp = T_part_world.linear() * d;
    if (auto h = solid.intersect(op, dp, t_max))
        best = RayHit{h->t, T_part_world.linear().transpose() * h->normal};
    if (support && d.z() < 0.0 && o.z() > 0.0) {
        const double t = -o.z() / d.z();
        const Eigen::Vector3d p = o + t * d;
        if (t < (best ? best->t : t_max) && std::abs(p.x()) <= support_half &&
            std::abs(p.y()) <= support_half)
            best = RayHit{t, Eigen::Vector3d::UnitZ()};
    }
    return best;
}

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
    SimResult out;
    SimTruth& truth = out.truth;
    truth.temperature_c = opt.temperature_c;
    truth.growth = recipe.material.growth(opt.temperature_c);
    truth.range_noise_mm = cell.sensor.range_noise_mm;
    truth.support_half_size_mm = cell.support_half_size_mm;
    draw_dimensions(recipe, opt.dimension_sigma_mm, rng, truth);
    const core::AxisymmetricSolid solid = truth.solid(recipe);
    double bottom_radius = 0.0;
    for (const auto& s : solid.boundary())
        if (!s.cylinder && s.value <= 1e-9) bottom_radius = std::max(bottom_radius, s.hi);
    truth.T_world_part =
        opt.T_world_part ? *opt.T_world_part : random_placement(cell, bottom_radius, rng);
    const Eigen::Isometry3d T_part_world = truth.T_world_part.inverse();
    if (opt.occluded_fraction > 0) {
        std::uniform_real_distribution<double> az(0.0, 2.0 * std::numbers::pi);
        truth.occluded_from_rad = az(rng);
        truth.occluded_rad = 2.0 * std::numbers::pi * std::min(1.0, opt.occluded_fraction);
    }
    // Rays that hit the part inside the occluded sector return nothing.
    auto occluded = [&](const Eigen::Vector3d& p_world) {
        if (truth.occluded_rad <= 0) return false;
        const Eigen::Vector3d q = T_part_world * p_world;
        if (std::abs(solid.distance(q)) > 1e-3) return false;  // the support, not the part
        double a = std::atan2(q.y(), q.x()) - truth.occluded_from_rad;
        a -= 2.0 * std::numbers::pi * std::floor(a / (2.0 * std::numbers::pi));
        return a < truth.occluded_rad;
    };

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
    std::mt19937_64 scan_rng(opt.scan_seed ? *opt.scan_seed : rng());
    const Vibration vib(cell.vibration, 0.0, t_end, scan_rng);

    const std::int64_t t0_ns = opt.t0_ns ? opt.t0_ns
                                         : std::chrono::duration_cast<std::chrono::nanoseconds>(
                                               std::chrono::system_clock::now().time_since_epoch())
                                               .count();
    core::Recording& rec = out.recording;
    rec.part_id = opt.part_id;
    rec.recipe = recipe.name;
    rec.captured_at = opt.captured_at.empty() ? iso8601_utc(t0_ns) : opt.captured_at;
    rec.temperature_c = opt.temperature_c;

    std::normal_distribution<double> gauss(0.0, 1.0);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    const double cos_max_incidence = std::cos(s.max_incidence_deg * kDeg);
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

        // Ray directions in the camera frame, fixed for the face.
        std::vector<Eigen::Vector3d> dir_cam(s.width);
        for (int i = 0; i < s.width; ++i)
            dir_cam[i] = Eigen::Vector3d((i - 0.5 * (s.width - 1)) * s.pitch_mm, 0.0, s.standoff_mm)
                             .normalized();

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
            const Eigen::Vector3d imager = origin + R * s.camera_center_mm;
            for (int i = 0; i < s.width; ++i) {
                const Eigen::Vector3d d = R * dir_cam[i];
                const auto hit = cast(solid, T_part_world, fc.support_visible,
                                      cell.support_half_size_mm, origin, d, 1e4);
                if (!hit) continue;
                const Eigen::Vector3d p = origin + hit->t * d;
                if (occluded(p)) continue;
                const double range_z = hit->t * dir_cam[i].z();
                if (range_z < s.min_range_mm || range_z > s.max_range_mm) continue;
                if (std::abs(hit->normal.dot(d)) < cos_max_incidence) continue;
                // Triangulation needs the imager to see the lit point.
                const Eigen::Vector3d to_imager = imager - p;
                const double dist = to_imager.norm();
                if (hit->normal.dot(to_imager) * hit->normal.dot(-d) <= 0.0) continue;
                if (cast(solid, T_part_world, false, 0.0, p + 1e-6 * to_imager / dist,
                         to_imager / dist, dist))
                    continue;
                if (u01(scan_rng) < s.dropout_fraction) continue;
                double along = s.range_noise_mm * gauss(scan_rng);
                if (u01(scan_rng) < s.spike_fraction) {
                    along = s.spike_range_mm * (2.0 * u01(scan_rng) - 1.0);
                    ft.spike[k * s.width + i] = 1;
                    ++ft.n_spikes;
                }
                const double tm = hit->t + along;
                face.profiles_mm[(k * s.width + i) * 2] = static_cast<float>(tm * dir_cam[i].x());
                face.profiles_mm[(k * s.width + i) * 2 + 1] =
                    static_cast<float>(tm * dir_cam[i].z());
            }
        }

        // Accelerometer in the head: a_acc = R_accᵀ·(ü/1000 + g_up) + bias + noise, clipped.
        const auto& a = cell.accel;
        const Eigen::Matrix3d R_world_accel = R * fc.R_camera_accel;
        const double noise_mps2 = a.noise_density_ug * 1e-6 * kG * std::sqrt(a.rate_hz / 2.0);
        const double clip = a.range_g * kG;
        const Eigen::Vector3d bias(a.bias_mps2 * (2 * u01(scan_rng) - 1),
                                   a.bias_mps2 * (2 * u01(scan_rng) - 1),
                                   a.bias_mps2 * (2 * u01(scan_rng) - 1));
        const double ta = t_start[j] - a.margin_s;
        const double tb = t_start[j] + static_cast<double>(n - 1) / s.line_rate_hz + a.margin_s;
        const auto n_acc = static_cast<std::int64_t>(std::floor((tb - ta) * a.rate_hz)) + 1;
        std::int64_t last_ns = std::numeric_limits<std::int64_t>::min();
        for (std::int64_t q = 0; q < n_acc; ++q) {
            double tq = ta + static_cast<double>(q) / a.rate_hz;
            if (a.jitter_ns > 0) tq += a.jitter_ns * 1e-9 * (2 * u01(scan_rng) - 1);
            const std::int64_t tq_ns = t0_ns + std::llround(tq * kNsPerS);
            if (tq_ns <= last_ns) continue;
            last_ns = tq_ns;
            const Eigen::Vector3d acc_world =
                vib.acceleration_mmps2(tq) / 1000.0 + Eigen::Vector3d(0, 0, kG);
            Eigen::Vector3d acc = R_world_accel.transpose() * acc_world + bias;
            for (int c = 0; c < 3; ++c) {
                acc[c] = std::clamp(acc[c] + noise_mps2 * gauss(scan_rng), -clip, clip);
                face.accel_mps2.push_back(static_cast<float>(acc[c]));
            }
            face.accel_times_ns.push_back(tq_ns);
        }
        rec.faces.push_back(std::move(face));
        truth.faces.push_back(std::move(ft));
    }
    return out;
}

}  // namespace hotgauge::sim
