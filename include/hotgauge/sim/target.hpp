#pragma once
// The virtual sensor's camera for image-mode sensor calibration (docs/calibration.md "Sensor"):
// a pinhole camera with lens distortion beside the laser, as a real laser-line head has, its true
// intrinsics and laser plane, and the images of a checkerboard it takes at given poses, lit and
// with only the laser line on it. Rendered by ray casting each pixel's centre, the edges blurred
// by the optics analytically (σ 0.6 px by default, in the board's plane at the pixel's depth).
#include <Eigen/Geometry>
#include <cstdint>
#include <random>
#include <vector>

#include "hotgauge/calib/sensor.hpp"
#include "hotgauge/calib/sensor_stage.hpp"
#include "hotgauge/sim/simulator.hpp"

namespace hotgauge::sim {

struct VirtualSensorCamera {
    calib::PinholeCamera camera;
    calib::LaserPlane plane;  // camera frame
    // Camera frame → the sensor's laser frame (x along the line, y the plane's normal, z range).
    Eigen::Isometry3d T_laser_camera = Eigen::Isometry3d::Identity();
};

// The head of `sensor`: the camera at its imager position (SensorConfig::imager_mm), looking at the
// middle of the measuring range, the field covering the fan's width; some distortion.
VirtualSensorCamera design_sensor_camera(const SensorConfig& sensor);

// `n` board poses (camera frame) a technician would take: the board centred on the laser plane
// at random places of the field, tilted up to 55°, every corner in the image. From `seed`.
std::vector<Eigen::Isometry3d> target_poses(const VirtualSensorCamera& head,
                                            const calib::Checkerboard& board, int n,
                                            std::uint64_t seed);

struct RenderOptions {
    double blur_px = 0.6;   // σ of the optics' blur on a board square's edge facing the camera
    double noise_dn = 1.0;  // σ of the pixels' noise, digital numbers of 255
};

class TargetRenderer {
  public:
    explicit TargetRenderer(const calib::PinholeCamera& camera, RenderOptions options = {});
    // The lit board at T_camera_board (board frame: corner (i, j) at (i, j)·square, z = 0).
    calib::GrayImage board(const calib::Checkerboard& b, const Eigen::Isometry3d& T_camera_board,
                           std::mt19937_64& rng) const;
    // The same pose in the dark: only the laser sheet (Gaussian, σ 0.25 mm) where it meets it.
    calib::GrayImage laser(const calib::Checkerboard& b, const Eigen::Isometry3d& T_camera_board,
                           const calib::LaserPlane& plane, std::mt19937_64& rng) const;

  private:
    template <class Shade>
    calib::GrayImage render(const Eigen::Isometry3d& T_camera_board, Shade shade,
                            std::mt19937_64& rng) const;
    calib::PinholeCamera camera_;
    RenderOptions options_;
    std::vector<float> rays_;  // per pixel, per sample: undistorted (x, y) at z = 1
};

// A precision stage's plan for calibrating the sensor (docs/calibration.md "Sensor on a stage"):
// the plate level at `level` heights, and at ±tilt_deg at each `tilted` height (laser frame).
struct StagePlan {
    std::vector<double> level_mm, tilted_mm;
    double tilt_deg = 30.0;
};
// 25 level heights over the measuring range (40 and 20 mm inside its ends: the virtual head's
// first row sees 625 mm), 7 tilted ones at ±30°.
StagePlan default_stage_plan(const SensorConfig& sensor);

// The laser images the head takes of a flat plate on the stage, with the heights and tilts the
// stage reports (exact). From `seed`.
std::vector<calib::StageReading> stage_readings(const VirtualSensorCamera& head,
                                                const StagePlan& plan, std::uint64_t seed,
                                                RenderOptions options = {});

}  // namespace hotgauge::sim
