#include "hotgauge/sim/geometry.hpp"

#include <cmath>
#include <numbers>
#include <random>

namespace hotgauge::sim {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

Eigen::Vector3d random_unit(std::mt19937_64& rng) {
    std::normal_distribution<double> n(0.0, 1.0);
    Eigen::Vector3d v(n(rng), n(rng), n(rng));
    return v.normalized();
}

// A rotation by an angle uniform in [0, max_deg] about a random axis.
Eigen::Matrix3d random_rotation(std::mt19937_64& rng, double max_deg) {
    const double a = std::uniform_real_distribution<double>(0.0, max_deg * kDeg)(rng);
    return Eigen::AngleAxisd(a, random_unit(rng)).toRotationMatrix();
}

double uniform(std::mt19937_64& rng, double half) {
    return std::uniform_real_distribution<double>(-half, half)(rng);
}

}  // namespace

calib::SensorModel sensor_model(const SensorConfig& s) {
    calib::SensorModel m;
    m.design() = s.design();
    return m;
}

calib::Calibration nominal_calibration(const CellConfig& cell, const std::string& source,
                                       const std::string& calibrated_at) {
    calib::Calibration c;
    c.calibrated_at = calibrated_at;
    c.method = "nominal";
    c.source = source;
    c.sensor = sensor_model(cell.sensor);
    for (const auto& f : cell.faces) {
        calib::FaceCalibration g;
        g.geometry() = f.geometry();
        c.faces.push_back(g);
    }
    c.clock_offset_ns = cell.clock_offset_ns;
    return c;
}

calib::Calibration perturbed_calibration(const calib::Calibration& nominal, std::uint64_t seed,
                                         const Perturbation& p) {
    std::mt19937_64 rng(seed);
    calib::Calibration t = nominal;
    t.method = "virtual-truth";
    t.source = nominal.source + " perturbed, seed " + std::to_string(seed);
    t.residuals.clear();
    // One head, moved between the faces: one accelerometer mount and bias.
    const Eigen::Matrix3d mount = random_rotation(rng, p.accel_mount_deg);
    for (int c = 0; c < 3; ++c) t.accel_bias_mps2[c] = uniform(rng, p.accel_bias_mps2);
    t.clock_offset_ns = std::llround(uniform(rng, p.clock_offset_ms) * 1e6);
    for (auto& f : t.faces) {
        const double r = p.translation_mm * std::cbrt(std::uniform_real_distribution<>(0, 1)(rng));
        f.T_world_camera.translation() += r * random_unit(rng);
        f.T_world_camera.linear() =
            random_rotation(rng, p.rotation_deg) * f.T_world_camera.linear();
        f.scan_direction = (random_rotation(rng, p.direction_deg) * f.scan_direction).normalized();
        f.travel_scale *= 1.0 + uniform(rng, p.travel_scale);
        f.R_camera_accel = f.R_camera_accel * mount;
    }
    return t;
}

core::Result<CellConfig> with_geometry(CellConfig cell, const calib::Calibration& truth,
                                       const std::string& truth_file) {
    const calib::SensorModel s = sensor_model(cell.sensor);
    const calib::SensorModel& m = truth.sensor;
    if (s.model != m.model || s.width != m.width || s.pitch_mm != m.pitch_mm ||
        s.standoff_mm != m.standoff_mm || s.baseline_mm != m.baseline_mm)
        return core::make_error(truth_file +
                                ": its sensor model is not the cell config's sensor (the "
                                "simulator renders with the config's)");
    for (auto& f : cell.faces) {
        const calib::FaceCalibration* g = truth.face(f.name);
        if (!g)
            return core::make_error(truth_file + ": no face '" + f.name + "' (the cell has it)");
        f.geometry() = g->geometry();  // the same name: found by it
    }
    cell.clock_offset_ns = truth.clock_offset_ns;
    cell.accel.fixed_bias_mps2 = truth.accel_bias_mps2;
    return cell;
}

}  // namespace hotgauge::sim
