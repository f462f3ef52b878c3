#pragma once
// Sensor calibration in image mode (docs/calibration.md "Sensor"): the camera of a laser-line
// head as a pinhole with lens distortion, and the laser plane in its frame, from images of a
// checkerboard at several poses, each taken once lit and once with only the laser line on it
// (OpenCV calib3d: findChessboardCorners, cornerSubPix, calibrateCamera, whose board poses cut
// the laser rays). A pixel of the laser line
// triangulates to the point where its ray meets the laser plane.
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "hotgauge/acquire/triangulation.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::calib {

struct PinholeCamera {
    int width = 2048, height = 1088;
    double fx = 0, fy = 0, cx = 0, cy = 0;
    std::array<double, 5> distortion{};  // OpenCV's k1, k2, p1, p2, k3
};

// The laser plane in the camera frame: points X with normal·X = offset_mm (normal unit).
struct LaserPlane {
    Eigen::Vector3d normal = Eigen::Vector3d::UnitY();
    double offset_mm = 0.0;
};

struct Checkerboard {
    int cols = 11, rows = 8;  // inner corners
    double square_mm = 20.0;
};

// An 8-bit grey image, row-major.
struct GrayImage {
    int width = 0, height = 0;
    std::vector<std::uint8_t> pixels;
    bool empty() const { return pixels.empty(); }
};

// One pose of the board: lit (the checkerboard), and with only the laser line (may be empty).
struct TargetView {
    GrayImage board;
    GrayImage laser;
};

struct SensorCalibration {
    PinholeCamera camera;
    LaserPlane plane;
    double reprojection_rms_px = 0.0;  // over every corner of every view
    double plane_rms_mm = 0.0;         // laser points off the fitted plane
    int laser_points = 0;
    int views = 0;
};

// Errors name the image: "target not found in image 3", too few views (3), a laser image
// without a line, laser lines that do not fix a plane (all on one line).
core::Result<SensorCalibration> calibrate_sensor(const std::vector<TargetView>& views,
                                                 const Checkerboard& board);

// The views file (docs/calibration.md "Sensor"): format hotgauge-sensor-views-1, the board
// {cols, rows, square_mm} and `views`, a list of {board: PNG, laser: PNG} (8-bit grey; laser
// optional), paths relative to the file. Errors name file:line and the key, or the image.
struct SensorViews {
    Checkerboard board;
    std::vector<TargetView> views;
};
core::Result<SensorViews> read_sensor_views(const std::filesystem::path& file);
// Writes the images as DIR/viewNN-board.png, viewNN-laser.png and DIR/views.yaml.
core::Result<void> write_sensor_views(const SensorViews& views, const std::filesystem::path& dir);

// Pixel (u, v) → the camera-frame point where its ray meets the laser plane; NaN when the ray
// is parallel to the plane or meets it behind the camera.
Eigen::Vector3d triangulate(const PinholeCamera& camera, const LaserPlane& plane, double u_px,
                            double v_px);

// The laser frame of a calibrated head, as the profiles use it (y the plane's normal, x the
// camera's x in the plane, z away from the camera, the origin where every image column's plane
// meets the laser plane, so that each column is a ray from it): camera frame → laser frame.
// Any rigid choice would do (the faces' alignment absorbs it); this one makes each column a ray.
// Needs the plane across the camera's rows (|normal.y| well above 0; fit_triangulation checks).
Eigen::Isometry3d laser_frame(const SensorCalibration& calibration);

// The calibration as the acquisition's calibrated triangulation model (acquire::CalibratedModel:
// per column z a rational function of the row, x/z a polynomial, so the lens's distortion is
// followed): sampled every `step_px` rows over the image, the points in laser_frame's
// coordinates, fitted by acquire::fit_calibrated_model.
core::Result<acquire::CalibrationFit> fit_triangulation(const SensorCalibration& calibration,
                                                        int step_px = 8, int degree = 3,
                                                        int x_degree = 3);

// Per column of a laser image: the stripe's sub-pixel row by the acquisition's own extraction
// (acquire::extract_stripe, Gaussian 3-point refinement), NaN where the column has no stripe.
std::vector<double> stripe_rows(const GrayImage& laser);

}  // namespace hotgauge::calib
