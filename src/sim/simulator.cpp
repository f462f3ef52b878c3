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

namespace {

std::vector<const FaceConfig*> faces_to_scan(const CellConfig& cell, const SimOptions& opt) {
    std::vector<const FaceConfig*> faces;
    for (const auto& f : cell.faces)
        if (opt.faces.empty() ||
            std::find(opt.faces.begin(), opt.faces.end(), f.name) != opt.faces.end())
            faces.push_back(&f);
    return faces;
}

// What the cell's software writes for a face: the calibration in force, or the truth.
struct Recorded {
    core::FaceGeometry geometry;
    std::int64_t clock_offset_ns;
};

core::Result<Recorded> recorded_geometry(const FaceConfig& fc, const CellConfig& cell,
                                         const SimOptions& opt) {
    if (!opt.in_force) return Recorded{fc.geometry(), cell.clock_offset_ns};
    const calib::FaceCalibration* g = opt.in_force->face(fc.name);
    if (!g)
        return core::make_error("simulate: the calibration in force has no face '" + fc.name + "'");
    return Recorded{g->geometry(), opt.in_force->clock_offset_ns};
}

// The accelerometer record of one face: a_acc = R_accᵀ·(ü/1000 + g_up) + bias + noise, clipped,
// on the accelerometer's clock (the sim's time axis), from t_first − margin to t_last + margin.
void record_accel(const CellConfig& cell, const FaceConfig& fc, const Vibration& vib,
                  double t_first, double t_last, std::int64_t t0_ns, RandomStream& rng,
                  core::FaceScan& face) {
    const auto& a = cell.accel;
    const AccelHead head(a, fc.T_world_camera.linear() * fc.R_camera_accel, rng);
    const double ta = t_first - a.margin_s;
    const auto n_acc =
        static_cast<std::int64_t>(std::floor((t_last + a.margin_s - ta) * a.rate_hz)) + 1;
    std::int64_t last_ns = std::numeric_limits<std::int64_t>::min();
    for (std::int64_t q = 0; q < n_acc; ++q) {
        double tq = ta + static_cast<double>(q) / a.rate_hz;
        if (a.jitter_ns > 0) tq += a.jitter_ns * 1e-9 * (2 * rng.uniform() - 1);
        const std::int64_t tq_ns = t0_ns + std::llround(tq * kNsPerS);
        if (tq_ns <= last_ns) continue;
        last_ns = tq_ns;
        const Eigen::Vector3f acc = head.sample(vib, tq, rng);
        face.accel_mps2.insert(face.accel_mps2.end(), acc.data(), acc.data() + 3);
        face.accel_times_ns.push_back(tq_ns);
    }
}

// Scans one face starting at t_start (s, sim time axis): profiles at the true pose (nominal +
// travel × travel_scale + vibration), written as the software in force records them.
core::Result<void> scan_face(const Scene& scene, const CellConfig& cell, const FaceConfig& fc,
                             const SimOptions& opt, const Vibration& vib, double t_start,
                             std::int64_t n, std::int64_t t0_ns, RandomStream& rng,
                             core::FaceScan& face, FaceTruth& ft) {
    const auto& s = cell.sensor;
    auto rg = recorded_geometry(fc, cell, opt);
    if (!rg) return rg.error();
    face.geometry() = rg->geometry;
    face.name = ft.name = fc.name;
    face.clock_offset_ns = rg->clock_offset_ns;
    face.geometry_from_calibration = true;  // as the cell's software writes it
    face.width = s.width;
    face.profiles_mm.assign(static_cast<std::size_t>(n * s.width * 2),
                            std::numeric_limits<float>::quiet_NaN());
    ft.spike.assign(static_cast<std::size_t>(n * s.width), 0);
    std::vector<RayReturn> returns;
    for (std::int64_t k = 0; k < n; ++k) {
        const double tk = t_start + static_cast<double>(k) / s.line_rate_hz;
        const double commanded = static_cast<double>(k) * fc.profile_spacing_mm;
        // Camera clock = true − the cell's offset; the software adds the offset it believes.
        face.profile_times_ns.push_back(t0_ns + std::llround(tk * kNsPerS) - cell.clock_offset_ns +
                                        rg->clock_offset_ns);
        face.profile_positions_mm.push_back(commanded * rg->geometry.travel_scale);
        const Eigen::Vector3d u = vib.displacement_mm(tk);
        ft.displacement_mm.push_back(u);
        const Eigen::Vector3d origin =
            fc.T_world_camera.translation() + commanded * fc.travel_scale * fc.scan_direction + u;
        scene.cast_profile(fc, origin, rng, returns);
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
    record_accel(cell, fc, vib, t_start, t_start + static_cast<double>(n - 1) / s.line_rate_hz,
                 t0_ns, rng, face);
    return {};
}

// Every requested face of `scene`, one after the other with the robot's move between them.
core::Result<SimResult> scan_scene(const Scene& scene, const std::string& recipe_name,
                                   const CellConfig& cell, const SimOptions& opt,
                                   std::uint64_t scan_seed) {
    const std::vector<const FaceConfig*> faces = faces_to_scan(cell, opt);
    std::vector<double> t_start(faces.size());
    std::vector<std::int64_t> n_prof(faces.size());
    double t = cell.accel.margin_s;
    for (std::size_t j = 0; j < faces.size(); ++j) {
        n_prof[j] = static_cast<std::int64_t>(
                        std::floor(faces[j]->scan_length_mm / faces[j]->profile_spacing_mm)) +
                    1;
        t_start[j] = t;
        t += static_cast<double>(n_prof[j]) / cell.sensor.line_rate_hz + cell.face_gap_s;
    }
    const double t_end = t + cell.accel.margin_s;
    // Everything of this scan (vibration, sensor noise, accelerometer) from its own stream, so
    // the same part can be scanned again under other vibration (scan_seed).
    RandomStream rng(scan_seed);
    const Vibration vib(cell.vibration, 0.0, t_end, rng.engine);

    const std::int64_t t0_ns = opt.t0_ns ? opt.t0_ns : core::realtime_ns();
    SimResult out;
    out.truth = scene.truth();
    core::Recording& rec = out.recording;
    rec.part_id = opt.part_id;
    rec.recipe = recipe_name;
    rec.captured_at = opt.captured_at.empty() ? core::iso8601_utc(t0_ns) : opt.captured_at;
    rec.temperature_c = opt.temperature_c;
    for (std::size_t j = 0; j < faces.size(); ++j) {
        core::FaceScan face;
        FaceTruth ft;
        if (auto r = scan_face(scene, cell, *faces[j], opt, vib, t_start[j], n_prof[j], t0_ns, rng,
                               face, ft);
            !r)
            return r.error();
        rec.faces.push_back(std::move(face));
        out.truth.faces.push_back(std::move(ft));
    }
    return out;
}

core::Result<void> check_faces(const CellConfig& cell, const SimOptions& opt) {
    if (cell.faces.empty()) return core::make_error("cell config: no faces to scan");
    if (cell.sensor.width < 2) return core::make_error("cell config: sensor.width must be >= 2");
    if (faces_to_scan(cell, opt).size() !=
        (opt.faces.empty() ? cell.faces.size() : opt.faces.size()))
        return core::make_error("simulate: a requested face is not in the cell config");
    return {};
}

}  // namespace

core::Result<SimResult> simulate(const core::Recipe& recipe, const CellConfig& cell,
                                 const SimOptions& opt) {
    if (auto ok = check_faces(cell, opt); !ok) return ok.error();
    std::mt19937_64 rng(opt.seed);
    auto scene = Scene::create(recipe, cell, opt, rng);
    if (!scene) return scene.error();
    const std::uint64_t scan_seed = opt.scan_seed ? *opt.scan_seed : rng();
    return scan_scene(*scene, recipe.name, cell, opt, scan_seed);
}

core::Result<SimResult> simulate_artifact(const calib::Artifact& artifact, const CellConfig& cell,
                                          const SimOptions& opt) {
    if (auto ok = check_faces(cell, opt); !ok) return ok.error();
    SimOptions cold = opt;
    cold.temperature_c = 20.0;
    const Scene scene = Scene::create_artifact(artifact, cell);
    return scan_scene(scene, artifact.name, cell, cold, opt.scan_seed ? *opt.scan_seed : opt.seed);
}

}  // namespace hotgauge::sim
