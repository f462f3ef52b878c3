// Image-mode sensor calibration on the virtual sensor's camera (docs/calibration.md "Sensor"):
// a checkerboard rendered at 40 poses, lit and with only the laser line, through a pinhole with
// distortion; OpenCV's calibration must reproject within 0.1 px; the laser points it
// triangulates are compared with where the true camera and plane put them, across the field
// (issue 16's 5 µm is not reached: see the bound below). Bad input is refused by name.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "hotgauge/calib/sensor.hpp"
#include "hotgauge/sim/simulator.hpp"
#include "hotgauge/sim/target.hpp"

namespace calib = hotgauge::calib;
namespace sim = hotgauge::sim;

namespace {

const std::string kConfig = HOTGAUGE_SOURCE_DIR "/config";

std::vector<calib::TargetView> views(const sim::VirtualSensorCamera& head,
                                     const calib::Checkerboard& b, int n, std::uint64_t seed) {
    const sim::TargetRenderer render(head.camera);
    std::mt19937_64 rng(seed);
    std::vector<calib::TargetView> out;
    for (const auto& T : sim::target_poses(head, b, n, seed))
        out.push_back({render.board(b, T, rng), render.laser(b, T, head.plane, rng)});
    return out;
}

}  // namespace

TEST(SensorCalibration, RecoversTheVirtualSensorsCameraAndLaserPlane) {
    auto cell = sim::read_cell_config(kConfig + "/cell.yaml");
    ASSERT_TRUE(cell);
    const sim::VirtualSensorCamera head = sim::design_sensor_camera(cell->sensor);
    const calib::Checkerboard board;
    const auto v = views(head, board, 40, 1);
    ASSERT_EQ(v.size(), 40u);

    auto cal = calib::calibrate_sensor(v, board);
    ASSERT_TRUE(cal) << cal.error().message;
    std::printf(
        "reprojection %.4f px; fx %.2f (true %.2f), cx %.2f (%.2f), k1 %.5f (%.5f); laser "
        "plane RMS %.4f mm over %d points\n",
        cal->reprojection_rms_px, cal->camera.fx, head.camera.fx, cal->camera.cx, head.camera.cx,
        cal->camera.distortion[0], head.camera.distortion[0], cal->plane_rms_mm, cal->laser_points);
    EXPECT_LT(cal->reprojection_rms_px, 0.1);
    // Across the field: every 32nd pixel whose ray meets the plane in the measuring range.
    double worst = 0.0, sum2 = 0.0;
    int n = 0;
    for (int v_px = 0; v_px < head.camera.height; v_px += 32)
        for (int u_px = 0; u_px < head.camera.width; u_px += 32) {
            const Eigen::Vector3d truth = calib::triangulate(head.camera, head.plane, u_px, v_px);
            const Eigen::Vector3d in_laser = head.T_laser_camera * truth;
            if (!truth.allFinite() || in_laser.z() < cell->sensor.min_range_mm ||
                in_laser.z() > cell->sensor.max_range_mm || std::abs(in_laser.x()) > 205.0)
                continue;
            const Eigen::Vector3d est = calib::triangulate(cal->camera, cal->plane, u_px, v_px);
            const double e = (est - truth).norm();
            worst = std::max(worst, e);
            sum2 += e * e;
            ++n;
        }
    std::printf("triangulated points: %d across the field, RMS %.2f µm, worst %.2f µm\n", n,
                std::sqrt(sum2 / n) * 1e3, worst * 1e3);
    EXPECT_GT(n, 500);
    // Issue 16 asks for 5 µm; this gives 58 µm RMS, 81 µm worst (docs/calibration.md "Sensor":
    // the depth scale is noise-limited). The bound guards the figure; the target is not met.
    EXPECT_LT(worst, 0.12);

    // Fitted into the acquisition's calibrated model: the same points through it, against the
    // calibration it was fitted to (what the fit adds) and against the truth.
    auto fit = calib::fit_triangulation(*cal);
    ASSERT_TRUE(fit) << fit.error().message;
    auto tri = hotgauge::acquire::Triangulation::calibrated(fit->model);
    ASSERT_TRUE(tri) << tri.error().message;
    const Eigen::Isometry3d T_camera_laser = calib::laser_frame(*cal).inverse();
    double fit_worst = 0.0, total_worst = 0.0;
    for (int v_px = 16; v_px < head.camera.height - 16; v_px += 32)
        for (int u_px = 16; u_px < head.camera.width - 16; u_px += 32) {
            const Eigen::Vector3d truth = calib::triangulate(head.camera, head.plane, u_px, v_px);
            const Eigen::Vector3d in_laser = head.T_laser_camera * truth;
            if (!truth.allFinite() || in_laser.z() < cell->sensor.min_range_mm ||
                in_laser.z() > cell->sensor.max_range_mm)
                continue;
            const auto p = tri->to_camera(u_px, v_px);
            if (!std::isfinite(p.x_mm)) continue;
            const Eigen::Vector3d model = T_camera_laser * Eigen::Vector3d(p.x_mm, 0, p.z_mm);
            fit_worst =
                std::max(fit_worst,
                         (model - calib::triangulate(cal->camera, cal->plane, u_px, v_px)).norm());
            total_worst = std::max(total_worst, (model - truth).norm());
        }
    std::printf(
        "calibrated model (degree 3): fit rms z %.2f µm, x %.2f µm; through it, worst %.2f "
        "µm from the calibration, %.2f µm from the truth\n",
        fit->rms_z_mm * 1e3, fit->rms_x_mm * 1e3, fit_worst * 1e3, total_worst * 1e3);
    // Its range law follows the calibration (z to 0.1 µm RMS); its x law, one ray per column
    // (u − u0)·pitch·z/ref, cannot follow the lens's distortion: 128 µm RMS in x. Issue 16's
    // "fitted into the calibrated model" needs per-column x there (docs/calibration.md).
    EXPECT_LT(fit->rms_z_mm, 0.001);
}

TEST(SensorCalibration, RefusesWhatCannotCalibrate) {
    auto cell = sim::read_cell_config(kConfig + "/cell.yaml");
    ASSERT_TRUE(cell);
    const sim::VirtualSensorCamera head = sim::design_sensor_camera(cell->sensor);
    const calib::Checkerboard board;
    auto v = views(head, board, 4, 2);
    ASSERT_EQ(v.size(), 4u);
    auto few = v;
    few.resize(2);
    auto r = calib::calibrate_sensor(few, board);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("2 views; at least 3"), std::string::npos);
    auto blank = v;
    std::fill(blank[2].board.pixels.begin(), blank[2].board.pixels.end(), 128);
    r = calib::calibrate_sensor(blank, board);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("target not found in image 3"), std::string::npos)
        << r.error().message;
    auto dark = v;
    std::fill(dark[1].laser.pixels.begin(), dark[1].laser.pixels.end(), 5);
    r = calib::calibrate_sensor(dark, board);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("no laser line in laser image 2"), std::string::npos)
        << r.error().message;
}
