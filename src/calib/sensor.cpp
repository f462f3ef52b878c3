#include "hotgauge/calib/sensor.hpp"

#include <Eigen/SVD>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "hotgauge/acquire/stripe.hpp"

namespace hotgauge::calib {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// OpenCV's iterations and tolerances: undistortPoints (rays), cornerSubPix (corners),
// calibrateCamera (not measured).
constexpr int kUndistortMaxIterations = 50;
constexpr double kUndistortEpsilon = 1e-12;
constexpr int kCornerMaxIterations = 100;
constexpr double kCornerEpsilon = 1e-4;
constexpr int kCalibrateMaxIterations = 300;
constexpr double kCalibrateEpsilon = 1e-16;
// cornerSubPix's half window (a 23 × 23 px window); docs/calibration.md: the window size, 5 to
// 21 px, changes nothing.
constexpr int kCornerHalfWindow = 11;
// A laser image gives at least this many points on its board, all of them together this many
// for the plane (not measured).
constexpr std::size_t kMinLaserPointsPerImage = 50;
constexpr std::size_t kMinLaserPoints = 100;
// The laser points' second singular value against the first: below this fraction they lie on
// one line (not measured).
constexpr double kMinLineSpread = 1e-3;
// The laser plane is across the camera's rows: its normal's y at least kMinNormalY, its x at
// most kMaxNormalX (laser_frame divides by the normal's y) (not measured).
constexpr double kMinNormalY = 0.05;
constexpr double kMaxNormalX = 0.99;

cv::Mat camera_matrix(const PinholeCamera& c) {
    return (cv::Mat_<double>(3, 3) << c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
}

cv::Mat distortion(const PinholeCamera& c) {
    return (cv::Mat_<double>(1, 5) << c.distortion[0], c.distortion[1], c.distortion[2],
            c.distortion[3], c.distortion[4]);
}

// The undistorted ray directions (z = 1) of pixels.
std::vector<cv::Point2d> rays(const PinholeCamera& c, const std::vector<cv::Point2d>& px) {
    std::vector<cv::Point2d> out;
    if (px.empty()) return out;
    cv::undistortPoints(px, out, camera_matrix(c), distortion(c), cv::noArray(), cv::noArray(),
                        cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS,
                                         kUndistortMaxIterations, kUndistortEpsilon));
    return out;
}

std::vector<cv::Point3f> board_points(const Checkerboard& b) {
    std::vector<cv::Point3f> p;
    for (int j = 0; j < b.rows; ++j)
        for (int i = 0; i < b.cols; ++i)
            p.emplace_back(static_cast<float>(i * b.square_mm), static_cast<float>(j * b.square_mm),
                           0.0f);
    return p;
}

// The laser points of one view in the camera frame: the stripe's pixels back-projected onto the
// board's plane (the board's pose T_camera_board).
std::vector<Eigen::Vector3d> laser_points(const PinholeCamera& cam, const GrayImage& laser,
                                          const Eigen::Isometry3d& T_camera_board) {
    const std::vector<double> rows = stripe_rows(laser);
    std::vector<cv::Point2d> px;
    for (std::size_t u = 0; u < rows.size(); ++u)
        if (std::isfinite(rows[u])) px.emplace_back(static_cast<double>(u), rows[u]);
    const Eigen::Vector3d n = T_camera_board.linear().col(2);
    const Eigen::Vector3d t = T_camera_board.translation();
    std::vector<Eigen::Vector3d> out;
    for (const auto& r : rays(cam, px)) {
        const Eigen::Vector3d d(r.x, r.y, 1.0);
        out.push_back(d * (n.dot(t) / n.dot(d)));
    }
    return out;
}

using Corners = std::vector<std::vector<cv::Point2f>>;

core::Result<void> check_views(const std::vector<TargetView>& views) {
    if (views.size() < 3)
        return core::make_error("sensor calibration: " + std::to_string(views.size()) +
                                " views; at least 3 board poses are needed");
    for (std::size_t i = 0; i < views.size(); ++i) {
        const GrayImage& g = views[i].board;
        const GrayImage& l = views[i].laser;
        const std::string n = std::to_string(i + 1);
        if (g.width <= 0 || g.height <= 0 ||
            g.pixels.size() != static_cast<std::size_t>(g.width) * g.height)
            return core::make_error("sensor calibration: image " + n + " has " +
                                    std::to_string(g.pixels.size()) + " pixels, not " +
                                    std::to_string(g.width) + " × " + std::to_string(g.height));
        if (g.width != views[0].board.width || g.height != views[0].board.height)
            return core::make_error("sensor calibration: image " + n +
                                    " is not the size of image 1");
        if (!l.empty() &&
            (l.width != g.width || l.height != g.height || l.pixels.size() != g.pixels.size()))
            return core::make_error("sensor calibration: laser image " + n +
                                    " is not the size of its board image");
    }
    return {};
}

core::Result<Corners> find_corners(const std::vector<TargetView>& views, const Checkerboard& b) {
    const cv::Size pattern(b.cols, b.rows);
    auto mat = [](const GrayImage& g) {  // a view of the pixels, no copy
        return cv::Mat(g.height, g.width, CV_8UC1, const_cast<std::uint8_t*>(g.pixels.data()));
    };
    Corners corners;
    for (std::size_t i = 0; i < views.size(); ++i) {
        std::vector<cv::Point2f> c;
        if (views[i].board.empty() ||
            !cv::findChessboardCorners(mat(views[i].board), pattern, c,
                                       cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE |
                                           cv::CALIB_CB_FAST_CHECK))
            return core::make_error("sensor calibration: target not found in image " +
                                    std::to_string(i + 1) + " (" + std::to_string(b.cols) + " × " +
                                    std::to_string(b.rows) + " inner corners)");
        cv::cornerSubPix(mat(views[i].board), c, cv::Size(kCornerHalfWindow, kCornerHalfWindow),
                         cv::Size(-1, -1),
                         cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS,
                                          kCornerMaxIterations, kCornerEpsilon));
        corners.push_back(std::move(c));
    }
    return corners;
}

Eigen::Isometry3d isometry(const cv::Mat& rvec, const cv::Mat& tvec) {
    cv::Mat R;
    cv::Rodrigues(rvec, R);
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) T.linear()(r, c) = R.at<double>(r, c);
        T.translation()(r) = tvec.at<double>(r);
    }
    return T;
}

// OpenCV's calibrateCamera over every view: the camera, each board's pose, the RMS.
SensorCalibration calibrate_camera(const Corners& corners, const Checkerboard& b, cv::Size size,
                                   std::vector<Eigen::Isometry3d>& T_camera_board) {
    const std::vector<std::vector<cv::Point3f>> objects(corners.size(), board_points(b));
    cv::Mat K, dist;
    std::vector<cv::Mat> rvecs, tvecs;
    SensorCalibration out;
    out.views = static_cast<int>(corners.size());
    out.reprojection_rms_px =
        cv::calibrateCamera(objects, corners, size, K, dist, rvecs, tvecs, 0,
                            cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS,
                                             kCalibrateMaxIterations, kCalibrateEpsilon));
    PinholeCamera& cam = out.camera;
    cam.width = size.width;
    cam.height = size.height;
    cam.fx = K.at<double>(0, 0);
    cam.fy = K.at<double>(1, 1);
    cam.cx = K.at<double>(0, 2);
    cam.cy = K.at<double>(1, 2);
    for (int k = 0; k < 5; ++k) cam.distortion[k] = dist.at<double>(0, k);
    T_camera_board.clear();
    for (std::size_t i = 0; i < rvecs.size(); ++i)
        T_camera_board.push_back(isometry(rvecs[i], tvecs[i]));
    return out;
}

// The laser plane (SVD) through every laser image's points on its board.
core::Result<void> fit_laser_plane(const std::vector<TargetView>& views,
                                   const std::vector<Eigen::Isometry3d>& T_camera_board,
                                   SensorCalibration& out) {
    std::vector<Eigen::Vector3d> pts;
    for (std::size_t i = 0; i < views.size(); ++i) {
        if (views[i].laser.empty()) continue;
        auto p = laser_points(out.camera, views[i].laser, T_camera_board[i]);
        if (p.size() < kMinLaserPointsPerImage)
            return core::make_error("sensor calibration: no laser line in laser image " +
                                    std::to_string(i + 1));
        pts.insert(pts.end(), p.begin(), p.end());
    }
    if (pts.size() < kMinLaserPoints)
        return core::make_error("sensor calibration: no laser images");
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : pts) mean += p / static_cast<double>(pts.size());
    Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
    for (const auto& p : pts) S += (p - mean) * (p - mean).transpose();
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(S, Eigen::ComputeFullU);
    if (!(svd.singularValues()(1) > kMinLineSpread * svd.singularValues()(0)))
        return core::make_error(
            "sensor calibration: the laser lines lie on one line: tilt the board between views");
    out.plane.normal = svd.matrixU().col(2);
    out.plane.offset_mm = out.plane.normal.dot(mean);
    if (out.plane.offset_mm < 0) out.plane.normal *= -1.0, out.plane.offset_mm *= -1.0;
    out.plane_rms_mm = std::sqrt(svd.singularValues()(2) / static_cast<double>(pts.size()));
    out.laser_points = static_cast<int>(pts.size());
    return {};
}

}  // namespace

std::vector<double> stripe_rows(const GrayImage& img) {
    acquire::StripeConfig c;  // the acquisition's stripe extraction, 8-bit, Gaussian peak fit
    c.max_value = 255;
    c.gaussian_refinement = true;
    const auto points =
        acquire::extract_stripe(img.pixels.data(), img.width, img.height, img.width, c);
    std::vector<double> out(points.size(), kNaN);
    for (std::size_t u = 0; u < points.size(); ++u)
        if (points[u].status == acquire::StripeStatus::kOk) out[u] = points[u].row;
    return out;
}

Eigen::Vector3d triangulate(const PinholeCamera& c, const LaserPlane& p, double u, double v) {
    const auto r = rays(c, {cv::Point2d(u, v)});
    const Eigen::Vector3d d(r[0].x, r[0].y, 1.0);
    const double den = p.normal.dot(d);
    if (std::abs(den) < 1e-12) return Eigen::Vector3d::Constant(kNaN);
    const double t = p.offset_mm / den;
    return t > 0 ? Eigen::Vector3d(t * d) : Eigen::Vector3d::Constant(kNaN);
}

Eigen::Isometry3d laser_frame(const SensorCalibration& c) {
    const Eigen::Vector3d y = c.plane.normal;
    const Eigen::Vector3d x = (Eigen::Vector3d::UnitX() - y * y.x()).normalized();
    Eigen::Vector3d z = x.cross(y);
    if (z.z() < 0) z = -z;
    Eigen::Matrix3d R_camera_laser;
    R_camera_laser << x, z.cross(x), z;
    // Every column's plane holds the camera's y axis through the centre: origin where it meets
    // the laser plane.
    const Eigen::Vector3d origin = Eigen::Vector3d::UnitY() * (c.plane.offset_mm / y.y());
    Eigen::Isometry3d T_camera_laser = Eigen::Isometry3d::Identity();
    T_camera_laser.linear() = R_camera_laser;
    T_camera_laser.translation() = origin;
    return T_camera_laser.inverse();
}

core::Result<acquire::CalibrationFit> fit_triangulation(const SensorCalibration& c, int step,
                                                        int degree, int x_degree) {
    if (std::abs(c.plane.normal.y()) < kMinNormalY || std::abs(c.plane.normal.x()) > kMaxNormalX)
        return core::make_error(
            "sensor calibration: the laser plane is not across the camera's rows (its normal " +
            std::string("must have a y component): the head's camera is turned on its axis"));
    const Eigen::Isometry3d T_laser_camera = laser_frame(c);
    std::vector<acquire::CalibrationSample> samples;
    for (int v = 0; v < c.camera.height; v += step)
        for (int u = 0; u < c.camera.width; ++u) {
            const Eigen::Vector3d X = triangulate(c.camera, c.plane, u, v);
            if (!X.allFinite()) continue;
            const Eigen::Vector3d L = T_laser_camera * X;
            samples.push_back({static_cast<double>(u), static_cast<double>(v), L.x(), L.z()});
        }
    acquire::CalibrationOptions o;
    o.width_px = c.camera.width;
    o.height_px = c.camera.height;
    o.degree = degree;
    o.x_degree = x_degree;
    return acquire::fit_calibrated_model(samples, o);
}

core::Result<SensorCalibration> calibrate_sensor(const std::vector<TargetView>& views,
                                                 const Checkerboard& b) {
    if (auto ok = check_views(views); !ok) return ok.error();
    auto corners = find_corners(views, b);
    if (!corners) return corners.error();
    std::vector<Eigen::Isometry3d> T_camera_board;
    SensorCalibration out = calibrate_camera(
        *corners, b, cv::Size(views.front().board.width, views.front().board.height),
        T_camera_board);
    if (auto ok = fit_laser_plane(views, T_camera_board, out); !ok) return ok.error();
    return out;
}

}  // namespace hotgauge::calib
