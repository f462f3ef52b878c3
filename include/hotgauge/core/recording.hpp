#pragma once
// The in-memory recording: everything the sensors delivered for one part
// (docs/recording-format.md). The simulator, the file reader and live acquisition fill it;
// everything downstream reads it and never knows where it came from.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace hotgauge::core {

// A face of the cell: where its camera is, which way the axis carries it, how the accelerometer
// sits in the head. The one type for it: a recording's face (FaceScan), a calibration's face
// (calib::FaceCalibration), the simulator's (sim::FaceConfig) and the scan settings
// (acquire::ScanConfig) all hold one. The cell's clock offset is not in it: the cell has one
// camera → accelerometer clock offset, not one per face (calibration.yaml, the simulator's cell
// config); a face scanned with it says so (FaceScan::clock_offset_ns).
struct FaceGeometry {
    std::string name;  // top, bottom, side1, side2, ... (a recording's folder name)
    Eigen::Isometry3d T_world_camera = Eigen::Isometry3d::Identity();  // at profile position 0
    Eigen::Vector3d scan_direction = Eigen::Vector3d::UnitY();         // unit, world frame
    Eigen::Matrix3d R_camera_accel = Eigen::Matrix3d::Identity();      // accel axes → camera axes
    double travel_scale = 1.0;  // true travel / commanded travel (axis speed or encoder error)

    FaceGeometry& geometry() { return *this; }
    const FaceGeometry& geometry() const { return *this; }
};

// One scanned face: its geometry (face.yaml's camera_to_world, scan_direction, accel_to_camera),
// N profiles of W points each, plus the accelerometer record.
struct FaceScan : FaceGeometry {
    // What the capturing software already applied from its calibration (face.yaml's optional
    // travel_scale and clock_offset_ns, docs/calibration.md): the positions are commanded travel
    // times travel_scale, the times camera clock + clock_offset_ns. A later calibration replaces
    // them (calib::apply_geometry). Other writers leave them out: 1 and 0.
    std::int64_t clock_offset_ns = 0;
    // face.yaml's optional `geometry_source: calibration`: the pose and axes are a calibration's
    // of a fixed head (this software writes it). Another calibration then replaces them; in a
    // recording without it, a head placed elsewhere keeps its placement (calib::apply_geometry).
    bool geometry_from_calibration = false;

    std::int64_t width = 0;                      // W points per profile
    std::vector<float> profiles_mm;              // N*W*2: (x, z) camera frame, NaN = no return
    std::vector<std::int64_t> profile_times_ns;  // N, strictly increasing
    std::vector<double> profile_positions_mm;    // N, travel along scan_direction
    std::vector<float> accel_mps2;               // K*3, accelerometer axes, gravity included
    std::vector<std::int64_t> accel_times_ns;    // K, strictly increasing

    std::int64_t n_profiles() const { return static_cast<std::int64_t>(profile_times_ns.size()); }
    std::int64_t n_accel() const { return static_cast<std::int64_t>(accel_times_ns.size()); }
    // Profile point (k, i) in the camera frame: (x, 0, z). NaN when there was no return.
    float x(std::int64_t k, std::int64_t i) const { return profiles_mm[(k * width + i) * 2]; }
    float z(std::int64_t k, std::int64_t i) const { return profiles_mm[(k * width + i) * 2 + 1]; }
    Eigen::Vector3d accel(std::int64_t j) const {
        return {accel_mps2[j * 3], accel_mps2[j * 3 + 1], accel_mps2[j * 3 + 2]};
    }
    // Nominal world point (recording-format-v1 "Geometry"):
    // P = camera_to_world · (x, 0, z, 1)ᵀ + profile_positions[k] · scan_direction.
    Eigen::Vector3d nominal_world_point(std::int64_t k, std::int64_t i) const {
        return T_world_camera * Eigen::Vector3d(x(k, i), 0.0, z(k, i)) +
               profile_positions_mm[k] * scan_direction;
    }
};

// A run of one face's profiles whose data is not known to the measurement's budget: the
// compensation could not follow the head there (docs/compensation.md "Gaps and degraded
// features"). Measurement leaves them out of every fit that can do without them.
struct UntrustedProfiles {
    std::int64_t first = 0, last = 0;  // profile indices, inclusive
    double t0_s = 0, t1_s = 0;         // their times, seconds after the face's first profile
    std::string cause;                 // "accelerometer gap", "clipped accelerometer samples", ...
};
// "top profiles 412–471 (1.061–1.121 s): accelerometer gap"
std::string describe(const std::string& face, const UntrustedProfiles& u);
// Per face, its untrusted runs; a face not in it is trusted throughout.
using FaceUntrusted = std::map<std::string, std::vector<UntrustedProfiles>>;

// Per face, the sensor's displacement at each profile (world frame, mm) as the compensation
// found it; the match and the measurement move the face's points back by it. A face not in it
// is taken as it was scanned.
using FaceDisplacements = std::map<std::string, std::vector<Eigen::Vector3d>>;

// The compensation's own error: the accelerometer's noise, integrated twice through the same
// high-pass, leaves the displacement wrong by a slowly varying e(t), stationary in the middle of
// the record (docs/compensation.md "Its own error"). Its autocovariance per world axis at lags
// k·lag_s, mm²; empty when unknown (no compensation, or too little record to tell).
struct DisplacementNoise {
    double lag_s = 0.0;
    std::array<std::vector<double>, 3> acov_mm2;
    bool known() const { return lag_s > 0.0 && !acov_mm2[0].empty(); }
    // Covariance of e_axis(t) and e_axis(t + tau): linear between lags, 0 beyond the last.
    // The lags reach past the error's correlation (4 / the high-pass corner, at least 2.5 s).
    double cov(int axis, double tau_s) const;
    // The bridged holes of the record (times of the usable samples either side, s from the first
    // profile) and what a bridge leaves of the displacement by the distance from one: rows
    // (distance up to, σ per world axis in mm), ascending; 0 beyond the last. Each hole's error is
    // one unknown per axis, the same at every profile it reaches, independent of other holes
    // (docs/compensation.md "Holes in u").
    std::vector<std::array<double, 2>> holes_s;
    std::vector<std::array<double, 2>> hole_sigma_mm;
    double hole_sigma(std::size_t hole, double t_s) const;
    // The world axes the holes' error is in: not z where the support plate gave every
    // profile's u_z (then acov_mm2[2] is the plate medians' own, docs/compensation.md).
    std::array<bool, 3> hole_axes = {true, true, true};
};
using FaceDisplacementNoise = std::map<std::string, DisplacementNoise>;

struct Recording {
    std::string part_id;
    std::string recipe;
    std::string captured_at;              // ISO 8601 UTC
    std::optional<double> temperature_c;  // absent = unknown
    std::vector<FaceScan> faces;          // in scan order
    std::vector<std::string> warnings;    // non-fatal findings of the reader

    const FaceScan* face(const std::string& name) const {
        for (const auto& f : faces)
            if (f.name == name) return &f;
        return nullptr;
    }
};

}  // namespace hotgauge::core
