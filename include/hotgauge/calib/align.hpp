#pragma once
// Face alignment from one multi-face scan of an artifact of known geometry, and the accelerometer's
// mount and bias from gravity in the same scan (docs/calibration.md "Faces" and "Accelerometer").
//
// Per face, the scan's points are P = R·(x, 0, z) + t + c·v, with c the commanded travel
// (profile_positions / the face's recorded travel_scale): nine unknowns, the camera pose (R, t) at
// position 0 and the travel vector v = travel_scale · scan_direction. They are fitted by
// Gauss–Newton to the artifact's surfaces (distance to each sphere, to each plane) starting from
// the recording's geometry, with the points re-assigned to the surfaces as the fit tightens.
#include <map>
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
    double max_start_error_mm = 20.0;   // how far the recording's geometry may be off
    double max_static_rms_mps2 = 0.05;  // accelerometer scatter of a face: the head must be still
    double max_gravity_residual_mps2 = 0.02;
};

struct FaceAlignment {
    FaceGeometry geometry;  // R_camera_accel as recorded (estimate_accel_mount measures it)
    double rms_mm = 0.0;    // point-to-surface RMS over the points used
    std::map<std::string, int> points;  // artifact surface → points used
    std::vector<std::string> spheres;   // the spheres this face saw
    int iterations = 0;
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
                                              const std::vector<FaceGeometry>& faces,
                                              const AlignLimits& limits = {});

// calibrate faces: every face of `recording` aligned, the accelerometer from gravity; the sensor
// model and the clock offset are `base`'s (the calibration in force). Residuals over a limit
// refuse the calibration with an error naming the face and the figure.
core::Result<Calibration> calibrate_faces(const Artifact& artifact,
                                          const core::Recording& recording, const Calibration& base,
                                          const AlignLimits& limits = {});

}  // namespace hotgauge::calib
