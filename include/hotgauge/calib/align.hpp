#pragma once
// Face alignment from one multi-face scan of an artifact of known geometry, and the accelerometer's
// mount and bias from gravity in the same scan (docs/calibration.md "Faces" and "Accelerometer").
//
// Per face, the scan's points are P = R·(x, 0, z) + t + c·v, with c the commanded travel
// (profile_positions / the face's recorded travel_scale): nine unknowns, the camera pose (R, t) at
// position 0 and the travel vector v = travel_scale · scan_direction. Each ball is found near
// where the recording's geometry puts it and the face placed from the balls' centres; then every
// point is fitted to its artifact surface by Ceres (Levenberg–Marquardt, rotation on SO(3), Cauchy
// loss), and the pose's covariance from Ceres says how well the artifact fixes it.
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/calib/artifact.hpp"
#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::calib {

// A calibration outside these is refused (docs/calibration.md "Limits").
struct AlignLimits {
    int min_spheres = 3;                // every face must see at least this many spheres
    int min_points_per_sphere = 200;    // a sphere with fewer points counts as not seen
    double max_rms_mm = 0.15;           // point-to-surface RMS of a face (3 × a 0.05 mm sensor)
    double max_start_error_mm = 40.0;   // how far the recording may put a ball (2° at 1 m + 5 mm)
    double max_static_rms_mps2 = 0.05;  // accelerometer scatter of a face: the head must be still
    double max_gravity_residual_mps2 = 0.02;
    // How well the artifact must fix each face (one standard deviation, from the covariance):
    // a quarter of the 0.02 mm measuring goal at the part, docs/calibration.md "Limits".
    double max_sigma_position_mm = 0.005;    // camera position at travel 0, each world axis
    double max_sigma_rotation_deg = 0.002;   // about each of the camera's axes
    double max_sigma_travel_ppm = 20.0;      // travel scale
    double max_sigma_direction_deg = 0.002;  // scan direction
};

// One standard deviation of a face's calibrated geometry.
struct PoseSigma {
    Eigen::Vector3d position_mm = Eigen::Vector3d::Zero();   // world x, y, z
    Eigen::Vector3d rotation_deg = Eigen::Vector3d::Zero();  // about the camera's x, y, z
    double travel_scale_ppm = 0.0;
    double direction_deg = 0.0;  // the scan direction's larger tilt
};

// How the points of one artifact surface fit it at the solution.
struct SurfaceFit {
    std::string name;
    int points = 0;
    double rms_mm = 0.0;   // signed distance from the surface, RMS
    double mean_mm = 0.0;  // and mean (a ball's size or the plate's height off its certificate)
};

// The residual over the scan: the mean signed distance of the points used, per cell of the scan
// coordinates (x along the line, commanded travel c).
struct ResidualMap {
    int columns = 0, rows = 0;  // x cells, travel cells
    double x0_mm = 0.0, x1_mm = 0.0, c0_mm = 0.0, c1_mm = 0.0;
    std::vector<float> mean_mm;  // rows × columns, row-major; NaN: no point in the cell
};

struct FaceAlignment {
    FaceCalibration geometry;  // R_camera_accel as recorded (estimate_accel_mount measures it)
    double rms_mm = 0.0;       // point-to-surface RMS over the points used
    std::map<std::string, int> points;  // artifact surface → points used
    std::vector<std::string> spheres;   // the spheres this face saw
    int iterations = 0;                 // Levenberg–Marquardt iterations, both rounds
    PoseSigma sigma;
    double start_error_mm = 0.0;       // how far the recording's geometry put the balls, worst
    std::vector<SurfaceFit> surfaces;  // every artifact surface with points
    ResidualMap map;
};

// Aligns one face; the error names the face and what is missing (too few spheres seen, ...).
core::Result<FaceAlignment> align_face(const Artifact& artifact, const core::FaceScan& face,
                                       const AlignLimits& limits = {});

struct AccelMount {
    Eigen::Matrix3d R_camera_accel = Eigen::Matrix3d::Identity();
    Eigen::Vector3d bias_mps2 = Eigen::Vector3d::Zero();
    double residual_mps2 = 0.0;  // RMS of gravity not explained, over the faces
};

// The accelerometer's mount (one head, moved between the faces) and bias from the mean reading
// of each face while the head is still: mean_j = R_caᵀ·R_wc,jᵀ·g_up + bias (Kabsch on the
// centred readings). The faces' orientations (`faces`, calibrated) must span two axes.
core::Result<AccelMount> estimate_accel_mount(const core::Recording& recording,
                                              const std::vector<FaceCalibration>& faces,
                                              const AlignLimits& limits = {});

// What `calibrate faces` found, face by face, accepted or not: what the commissioning report
// shows (report::commissioning_html).
struct FaceOutcome {
    std::string name;
    FaceCalibration recorded;              // the geometry the artifact recording claimed
    std::optional<FaceAlignment> aligned;  // when the face was aligned within the limits
    std::string refused;                   // else why not
};
struct Commissioning {
    std::string artifact;  // its name
    std::vector<FaceOutcome> faces;
    std::optional<Calibration> calibration;  // when every face and the accelerometer passed
    std::string refused;                     // else the first reason
    AlignLimits limits;
};

// Every face of `recording` aligned (each one even when another is refused), then the
// accelerometer; the calibration when all passed.
Commissioning commission_faces(const Artifact& artifact, const core::Recording& recording,
                               const Calibration& base, const AlignLimits& limits = {});

// calibrate faces: every face of `recording` aligned, the accelerometer from gravity; the sensor
// model and the clock offset are `base`'s (the calibration in force). Residuals over a limit
// refuse the calibration with an error naming the face and the figure.
core::Result<Calibration> calibrate_faces(const Artifact& artifact,
                                          const core::Recording& recording, const Calibration& base,
                                          const AlignLimits& limits = {});

}  // namespace hotgauge::calib
