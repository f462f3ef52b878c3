// Image-mode sensor calibration on the virtual sensor's camera (docs/calibration.md "Sensor"):
// a checkerboard rendered at 40 poses, lit and with only the laser line, through a pinhole with
// distortion; OpenCV's calibration must reproject within 0.1 px; the laser points it
// triangulates are compared with where the true camera and plane put them, across the field
// (issue 16's 5 µm is not reached: see the bound below). Bad input is refused by name.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
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

struct FieldError {
    int points = 0;
    double rms_mm = 0.0, worst_mm = 0.0;
};

// The calibration's triangulated laser points against the true camera and plane: every 32nd pixel
// whose ray meets the plane in the measuring range, across the field.
FieldError field_error(const sim::VirtualSensorCamera& head, const sim::SensorConfig& sensor,
                       const calib::SensorCalibration& cal) {
    FieldError f;
    double sum2 = 0.0;
    for (int v_px = 0; v_px < head.camera.height; v_px += 32)
        for (int u_px = 0; u_px < head.camera.width; u_px += 32) {
            const Eigen::Vector3d truth = calib::triangulate(head.camera, head.plane, u_px, v_px);
            const Eigen::Vector3d in_laser = head.T_laser_camera * truth;
            if (!truth.allFinite() || in_laser.z() < sensor.min_range_mm ||
                in_laser.z() > sensor.max_range_mm || std::abs(in_laser.x()) > 205.0)
                continue;
            const Eigen::Vector3d est = calib::triangulate(cal.camera, cal.plane, u_px, v_px);
            const double e = (est - truth).norm();
            f.worst_mm = std::max(f.worst_mm, e);
            sum2 += e * e;
            ++f.points;
        }
    f.rms_mm = std::sqrt(sum2 / std::max(f.points, 1));
    std::printf("triangulated points: %d across the field, RMS %.2f µm, worst %.2f µm\n", f.points,
                f.rms_mm * 1e3, f.worst_mm * 1e3);
    return f;
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
    const FieldError f = field_error(head, cell->sensor, *cal);
    EXPECT_GT(f.points, 500);
    // Issue 16 asks for 5 µm; this gives 58 µm RMS, 81 µm worst (docs/calibration.md "Sensor":
    // the depth scale is noise-limited). The bound guards the figure; the target is not met.
    EXPECT_LT(f.worst_mm, 0.12);

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
    // Both laws follow the calibration: z to 0.1 µm RMS, x (x/z per column, cubic in the row)
    // through the lens's distortion; through the model every point within 2 µm of it.
    EXPECT_LT(fit->rms_z_mm, 0.001);
    EXPECT_LT(fit->rms_x_mm, 0.001);
    EXPECT_LT(fit_worst, 0.002);
    // And the fan law alone (one ray per column) cannot: what the x law is for.
    auto fan = calib::fit_triangulation(*cal, 8, 3, 0);
    ASSERT_TRUE(fan) << fan.error().message;
    std::printf("fan law instead: x rms %.2f µm\n", fan->rms_x_mm * 1e3);
    EXPECT_GT(fan->rms_x_mm, 0.05);
}

// What limits the image mode: where cornerSubPix puts the corners against where the true camera
// images them, noise-free, for optics blurring an edge by σ 0.6, 1.0 and 1.5 px. The error is
// the detector's (it shrinks as the blur grows and with no noise at all), and the triangulation
// magnifies it: at 900 mm with a 300 mm baseline a row's error of 1 px is 0.6 mm of range.
TEST(SensorCalibration, CornerLocalisationAgainstTheTruth) {
    auto cell = sim::read_cell_config(kConfig + "/cell.yaml");
    ASSERT_TRUE(cell);
    const sim::VirtualSensorCamera head = sim::design_sensor_camera(cell->sensor);
    const calib::Checkerboard b;
    const auto& c = head.camera;
    const cv::Mat K = (cv::Mat_<double>(3, 3) << c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
    const cv::Mat D(1, 5, CV_64F, const_cast<double*>(c.distortion.data()));
    double previous = 1e9;
    for (double blur : {0.6, 1.0, 1.5}) {
        const sim::TargetRenderer render(c, {.blur_px = blur, .noise_dn = 0.0});
        std::mt19937_64 rng(3);
        double sum2 = 0.0;
        int n = 0;
        for (const auto& T : sim::target_poses(head, b, 8, 1)) {
            auto img = render.board(b, T, rng);
            const cv::Mat m(img.height, img.width, CV_8UC1, img.pixels.data());
            std::vector<cv::Point2f> found;
            ASSERT_TRUE(cv::findChessboardCorners(
                m, cv::Size(b.cols, b.rows), found,
                cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE));
            cv::cornerSubPix(
                m, found, cv::Size(11, 11), cv::Size(-1, -1),
                cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-4));
            std::vector<cv::Point3d> in_camera;
            for (int j = 0; j < b.rows; ++j)
                for (int i = 0; i < b.cols; ++i) {
                    const Eigen::Vector3d q =
                        T * Eigen::Vector3d(i * b.square_mm, j * b.square_mm, 0);
                    in_camera.emplace_back(q.x(), q.y(), q.z());
                }
            std::vector<cv::Point2d> truth;
            cv::projectPoints(in_camera, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, D, truth);
            // The detector may number the corners from the other end.
            if (std::hypot(found[0].x - truth[0].x, found[0].y - truth[0].y) > 5)
                std::reverse(found.begin(), found.end());
            for (std::size_t k = 0; k < truth.size(); ++k, ++n)
                sum2 += std::pow(found[k].x - truth[k].x, 2) + std::pow(found[k].y - truth[k].y, 2);
        }
        const double rms = std::sqrt(sum2 / n);
        std::printf("blur σ %.1f px, no noise: corners %.4f px RMS from the truth over %d\n", blur,
                    rms, n);
        EXPECT_LT(rms, previous);
        EXPECT_GT(rms, 0.002);  // not exact even noise-free: the detector's own error
        previous = rms;
    }
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
