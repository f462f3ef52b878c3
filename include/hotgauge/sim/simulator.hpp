#pragma once
// The scan simulator: a hub-a-like forging on the support, a line-laser triangulation sensor
// scanning its faces, press vibration and the accelerometer in the sensor head
// (docs/simulator.md). Writes what a real cell would record, plus the ground truth.
#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/acquire/triangulation.hpp"
#include "hotgauge/calib/artifact.hpp"
#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/core/forged.hpp"
#include "hotgauge/core/part.hpp"
#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/sim/vibration.hpp"

namespace hotgauge::sim {

// Line-laser triangulation sensor: its design (acquire::SensorDesign: the laser fan in the
// camera's y = 0 plane from the camera origin, ray i at x_i = (i − (W−1)/2)·pitch on the plane
// z = standoff, the imager at (0, baseline, 0) in the camera frame), and how it errs.
struct SensorConfig : acquire::SensorDesign {
    // The imager's centre in the camera frame (occlusion: it must see the lit point).
    Eigen::Vector3d imager_mm() const { return {0.0, baseline_mm, 0.0}; }
    double range_noise_mm = 0.05;     // σ along the ray
    double dropout_fraction = 0.01;   // random missing returns
    double spike_fraction = 0.002;    // gross outliers along the ray
    double spike_range_mm = 5.0;      // spikes are uniform in ±this along the ray
    double max_incidence_deg = 80.0;  // no return at grazing incidence
    double line_rate_hz = 1000.0;     // profiles per second
    // A return needs the imager (imager_mm) to see the lit point: shadows at steps.
    // false: a point wherever the laser ray hits first (the incidence limit still applies).
    bool imager_occlusion = true;
};

// A face of the simulated cell: its geometry (travel_scale: sim::with_geometry) and its scan.
struct FaceConfig : core::FaceGeometry {
    double scan_length_mm = 240.0;
    double profile_spacing_mm = 0.2;
    bool support_visible = true;  // the flat support plate (world z = 0) is in this scan
};

struct AccelConfig {
    double rate_hz = 2000.0;
    double noise_density_ug = 25.0;  // µg/√Hz, white
    double bias_mps2 = 0.01;         // per-axis bias drawn uniform in ±this
    double range_g = 8.0;            // output clips at ±range
    double margin_s = 1.0;           // record before the first and after the last profile
    double jitter_ns = 0.0;          // uniform timestamp jitter ±this (0: uniform grid)
    // Set: the sensor's bias (sim::with_geometry); unset: drawn per face in ±bias_mps2.
    std::optional<Eigen::Vector3d> fixed_bias_mps2;
};

struct PlacementConfig {
    double max_offset_mm = 40.0;  // random x, y offset on the support, uniform in ±this
    double max_tilt_deg = 0.0;    // random tilt (part on pins), uniform in [0, this]
};

struct CellConfig {
    SensorConfig sensor;
    std::vector<FaceConfig> faces;
    VibrationConfig vibration;
    AccelConfig accel;
    PlacementConfig placement;
    double support_half_size_mm = 200.0;
    double face_gap_s = 2.0;  // robot moves between face scans
    // The camera's clock runs this far behind the accelerometer's (the sim's time axis): a
    // profile taken at t carries the camera timestamp t − clock_offset_ns.
    std::int64_t clock_offset_ns = 0;
};

// Reads config/cell.yaml (docs/simulator.md); errors name file:line:key.
core::Result<CellConfig> read_cell_config(const std::filesystem::path& file);

// A coarser cell for unit tests: W/4 rays at 4× pitch, 1 mm profiles, 1 kHz accelerometer.
CellConfig quick(CellConfig cell);

struct SimOptions {
    std::uint64_t seed = 1;                  // the part: dimensions and pose
    std::optional<std::uint64_t> scan_seed;  // the scan: vibration, noise; default from seed
    double temperature_c = 20.0;
    std::optional<Eigen::Isometry3d> T_world_part;  // default: random yaw and offset
    double dimension_sigma_mm = 0.05;  // as-forged deviation of each level and diameter (cold)
    std::string part_id = "SIM-000001";
    std::string captured_at;         // default: now (UTC)
    std::int64_t t0_ns = 0;          // clock of the first accelerometer sample; 0: from now
    std::vector<std::string> faces;  // subset of the cell's faces; empty = all
    // Occlusion: a contiguous sector of the part, this fraction of the full turn at a random
    // azimuth, returns nothing in every face (a gripper finger, loose scale, steam).
    double occluded_fraction = 0.0;
    // The calibration in force: the recording's face.yaml geometry, positions (commanded travel ×
    // its travel_scale) and times (camera clock + its clock offset) as the cell's software writes
    // them with it. Unset: the cell's true geometry (a perfectly commissioned cell).
    std::optional<calib::Calibration> in_force;
    // As it leaves the press (docs/simulator.md "As-forged parts"): per wall a draft, per corner
    // a fillet and a die shift, drawn within the recipe's `forging` drawing (required), from
    // their own stream: the same seed gives the same dimensions and pose either way.
    bool forged = false;
    // Bad features: a recipe feature's name (or "Die shift", forged only) -> mm added to its true
    // value (a diameter's section, a height's upper level, the die shift's length).
    std::map<std::string, double> bad_mm;
};

struct FeatureTruth {
    std::string name;
    double hot_mm = 0, cold_mm = 0;
};

struct FaceTruth {
    std::string name;
    std::vector<Eigen::Vector3d> displacement_mm;  // true sensor displacement per profile, world
    std::vector<std::uint8_t> spike;               // N*W: 1 where the point is a simulated spike
    std::int64_t n_spikes = 0;
};

struct SimTruth {
    Eigen::Isometry3d T_world_part = Eigen::Isometry3d::Identity();
    double temperature_c = 20.0;
    double growth = 1.0;                         // 1 + α(T)·(T − 20)
    std::map<std::string, double> levels_mm;     // actual cold levels
    std::map<std::string, double> diameters_mm;  // actual cold diameters
    std::vector<FeatureTruth> features;
    std::vector<FaceTruth> faces;
    double range_noise_mm = 0;
    double support_half_size_mm = 0;
    double occluded_from_rad = 0, occluded_rad = 0;  // occluded sector, part-frame azimuth
    std::map<std::string, double> bad_mm;            // SimOptions::bad_mm as applied
    // As forged: the drawn shape, profiles and sharp-corner features (cold); its hot solid is
    // forged->solid(). Unset: sharp corners, vertical walls, one axis (solid() below).
    std::optional<core::ForgedPart> forged;
    // The hot part as scanned, part frame (when not forged).
    core::AxisymmetricSolid solid(const core::Recipe& recipe) const {
        return core::AxisymmetricSolid::from_recipe(recipe, levels_mm, diameters_mm, growth);
    }
};

struct SimResult {
    core::Recording recording;
    SimTruth truth;
};

core::Result<SimResult> simulate(const core::Recipe& recipe, const CellConfig& cell,
                                 const SimOptions& options);

// The artifact scanned instead of a part (cold; part.yaml recipe = the artifact's name): its
// spheres on invisible posts, the support plate where the face sees it. options.seed, the
// temperature, pose and occlusion are not used; the truth holds the per-face displacement only.
core::Result<SimResult> simulate_artifact(const calib::Artifact& artifact, const CellConfig& cell,
                                          const SimOptions& options);

// Ground truth beside a recording: DIR/truth.yaml (pose, features, per-face figures),
// DIR/part_pose.yaml (world_from_part, for `hotgauge measure --part-pose`), DIR/<face>/u_true.npy
// (N,3) <f8 mm and DIR/<face>/spikes.npy (N,W) |u1.
core::Result<void> write_truth(const SimTruth& truth, const std::filesystem::path& dir);

}  // namespace hotgauge::sim
