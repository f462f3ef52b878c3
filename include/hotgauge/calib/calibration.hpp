#pragma once
// The cell's measured geometry (docs/calibration.md): the sensor's triangulation model, each
// face's camera pose, scan direction and travel scale, the accelerometer's mount and bias, and
// the camera → accelerometer clock offset, with when, how and from what they were measured.
// One file, calibration.yaml; the daemon and `hotgauge measure --calibration` take the geometry
// from it, never from the simulator's cell config.
#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/acquire/scan.hpp"
#include "hotgauge/acquire/triangulation.hpp"
#include "hotgauge/calib/sensor.hpp"
#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/io/bytes.hpp"

namespace hotgauge::calib {

// A line-laser head: `direct_beam`, its design (acquire::SensorDesign, triangulated by
// acquire::design_direct_beam); or `pinhole`, an image-mode calibration (calibrate_sensor): the
// camera with its distortion and the laser plane, profiles in its laser_frame.
struct SensorModel : acquire::SensorDesign {
    std::string model = "direct_beam";  // direct_beam | pinhole | stage
    // model pinhole (width is the camera's; the direct-beam keys unused):
    PinholeCamera camera;
    LaserPlane plane;
    // model stage (`calibrate sensor --stage`): the pixel → mm map itself (width its width_px).
    acquire::CalibratedModel map;
};

// A face's measured geometry (core::FaceGeometry: camera pose at profile position 0, scan
// direction, travel scale, accelerometer axes → camera axes), with where it came from.
struct FaceCalibration : core::FaceGeometry {
    // `calibrate faces`: the pose the artifact recording's face.yaml gave this face. Another
    // tool's recording, which may place the head per part (stand-off, start), takes the
    // calibration as a correction of its own pose (apply_geometry).
    std::optional<Eigen::Isometry3d> recorded_camera_to_world;
};

struct Calibration {
    std::string calibrated_at;                // ISO 8601 UTC
    std::string method;                       // nominal | artifact | ... (docs/calibration.md)
    std::string source;                       // the artifact, target or file the geometry came from
    std::map<std::string, double> residuals;  // method-specific figures, mm / px / deg / µs
    SensorModel sensor;
    std::vector<FaceCalibration> faces;
    Eigen::Vector3d accel_bias_mps2 = Eigen::Vector3d::Zero();  // accelerometer axes
    std::int64_t clock_offset_ns = 0;  // added to camera timestamps: camera → accel clock

    const FaceCalibration* face(const std::string& name) const;
    // Whether the faces' geometry was measured (false: design values asserted, method `nominal`,
    // or only the sensor calibrated since, method `sensor`: its faces are to be aligned again).
    bool measured() const { return method != "nominal" && method != "sensor"; }
};

// Reads calibration.yaml; errors name file:line and key. Every face's rotations must be proper
// (orthonormal, det +1), scan directions unit, names unique, the sensor's ranges ordered.
core::Result<Calibration> read_calibration(const std::filesystem::path& file);
// The same on the file's text, `file` naming it in errors.
core::Result<Calibration> parse_calibration(std::string_view text,
                                            const std::filesystem::path& file);

// Writes calibration.yaml (full double precision, so reading it back gives the same numbers).
core::Result<void> write_calibration(const Calibration& c, const std::filesystem::path& file);

// A recording's faces take the calibration's geometry in place of their face.yaml's: camera
// pose, scan direction, accelerometer axes, and the profile positions scaled by travel_scale.
// The pose is replaced when this software wrote the recording (face.yaml's `geometry_source:
// calibration`: a fixed head, its pose a calibration's) or when the calibration does not say
// what pose it was made from. Another tool's recording keeps its own placement of the head and
// takes the calibration's correction of the mount: T = T_face.yaml · T_recorded⁻¹ · T_calibrated
// (T_recorded: `recorded_camera_to_world`, the artifact recording's claim).
// The profiles stay as recorded (they are millimetres already: the sensor model was applied at
// capture), and so do the times (one clock by the recording contract). A face the calibration
// does not hold is an error naming it and `calibration_file`; nothing is changed then.
core::Result<void> apply_geometry(const Calibration& c, const std::string& calibration_file,
                                  core::Recording& recording);

// The sensor model as the triangulation the acquisition uses: direct_beam, rows over the measuring
// range; pinhole, the calibration fitted into the calibrated model (fit_triangulation), whose
// camera must be `height_px` rows high.
core::Result<acquire::Triangulation> triangulation(const SensorModel& sensor, int height_px = 1088);

// The scan settings for face `face` of the calibrated cell: `scan` with the face's geometry (its
// travel scale applied to the positions), the cell's clock offset, and the recording marked as
// a calibration's geometry. The daemon's and `hotgauge grab`'s. A face the calibration does not
// hold is an error naming it.
core::Result<acquire::ScanConfig> scan_config(const Calibration& c, const std::string& face,
                                              acquire::ScanConfig scan);

}  // namespace hotgauge::calib
