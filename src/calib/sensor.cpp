#include "hotgauge/calib/sensor.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "hotgauge/acquire/stripe.hpp"

namespace hotgauge::calib {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

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
    cv::undistortPoints(
        px, out, camera_matrix(c), distortion(c), cv::noArray(), cv::noArray(),
        cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 50, 1e-12));
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

using Views = std::vector<const TargetView*>;
using Corners = std::vector<std::vector<cv::Point2f>>;

core::Result<void> check_views(const Views& views) {
    if (views.size() < 3)
        return core::make_error("sensor calibration: " + std::to_string(views.size()) +
                                " views; at least 3 board poses are needed");
    for (std::size_t i = 0; i < views.size(); ++i) {
        const GrayImage& g = views[i]->board;
        const GrayImage& l = views[i]->laser;
        const std::string n = std::to_string(i + 1);
        if (g.width <= 0 || g.height <= 0 ||
            g.pixels.size() != static_cast<std::size_t>(g.width) * g.height)
            return core::make_error("sensor calibration: image " + n + " has " +
                                    std::to_string(g.pixels.size()) + " pixels, not " +
                                    std::to_string(g.width) + " × " + std::to_string(g.height));
        if (g.width != views[0]->board.width || g.height != views[0]->board.height)
            return core::make_error("sensor calibration: image " + n +
                                    " is not the size of image 1");
        if (!l.empty() &&
            (l.width != g.width || l.height != g.height || l.pixels.size() != g.pixels.size()))
            return core::make_error("sensor calibration: laser image " + n +
                                    " is not the size of its board image");
    }
    return {};
}

core::Result<Corners> find_corners(const Views& views, const Checkerboard& b) {
    const cv::Size pattern(b.cols, b.rows);
    auto mat = [](const GrayImage& g) {  // a view of the pixels, no copy
        return cv::Mat(g.height, g.width, CV_8UC1, const_cast<std::uint8_t*>(g.pixels.data()));
    };
    Corners corners;
    for (std::size_t i = 0; i < views.size(); ++i) {
        std::vector<cv::Point2f> c;
        if (views[i]->board.empty() ||
            !cv::findChessboardCorners(mat(views[i]->board), pattern, c,
                                       cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE))
            return core::make_error("sensor calibration: target not found in image " +
                                    std::to_string(i + 1) + " (" + std::to_string(b.cols) + " × " +
                                    std::to_string(b.rows) + " inner corners)");
        cv::cornerSubPix(
            mat(views[i]->board), c, cv::Size(11, 11), cv::Size(-1, -1),
            cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-4));
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
    out.reprojection_rms_px = cv::calibrateCamera(
        objects, corners, size, K, dist, rvecs, tvecs, 0,
        cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 300, 1e-16));
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
core::Result<void> fit_laser_plane(const Views& views,
                                   const std::vector<Eigen::Isometry3d>& T_camera_board,
                                   SensorCalibration& out) {
    std::vector<Eigen::Vector3d> pts;
    for (std::size_t i = 0; i < views.size(); ++i) {
        if (views[i]->laser.empty()) continue;
        auto p = laser_points(out.camera, views[i]->laser, T_camera_board[i]);
        if (p.size() < 50)
            return core::make_error("sensor calibration: no laser line in laser image " +
                                    std::to_string(i + 1));
        pts.insert(pts.end(), p.begin(), p.end());
    }
    if (pts.size() < 100) return core::make_error("sensor calibration: no laser images");
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : pts) mean += p / static_cast<double>(pts.size());
    Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
    for (const auto& p : pts) S += (p - mean) * (p - mean).transpose();
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(S, Eigen::ComputeFullU);
    if (!(svd.singularValues()(1) > 1e-3 * svd.singularValues()(0)))
        return core::make_error(
            "sensor calibration: the laser lines lie on one line: tilt the board between views");
    out.plane.normal = svd.matrixU().col(2);
    out.plane.offset_mm = out.plane.normal.dot(mean);
    if (out.plane.offset_mm < 0) out.plane.normal *= -1.0, out.plane.offset_mm *= -1.0;
    out.plane_rms_mm = std::sqrt(svd.singularValues()(2) / static_cast<double>(pts.size()));
    out.laser_points = static_cast<int>(pts.size());
    return {};
}

// The joint fit on a stage: the camera, and per placement the board's pose with the carriage at
// 0 and the stage's axis in the board frame.
struct StageModel {
    PinholeCamera camera;
    std::vector<Eigen::Isometry3d> T_camera_board;  // carriage at 0
    std::vector<Eigen::Vector3d> axis;              // unit, board frame
};
struct StageObservation {
    int placement;  // 0 … placements − 1
    double stage_mm;
    const std::vector<cv::Point2f>* corners;
};
constexpr int kCameraParams = 9;     // fx fy cx cy k1 k2 p1 p2 k3
constexpr int kPlacementParams = 8;  // rotation vector, translation, the axis tilted two ways

Eigen::Isometry3d board_pose(const StageModel& m, int placement, double stage_mm) {
    Eigen::Isometry3d T = m.T_camera_board[placement];
    T.translation() += T.linear() * (stage_mm * m.axis[placement]);
    return T;
}

// Parameter k of the model moved by h.
void perturb(StageModel& m, int k, double h) {
    if (k < kCameraParams) {
        double* c[] = {&m.camera.fx, &m.camera.fy, &m.camera.cx, &m.camera.cy};
        if (k < 4)
            *c[k] += h;
        else
            m.camera.distortion[k - 4] += h;
        return;
    }
    const int p = (k - kCameraParams) / kPlacementParams,
              j = (k - kCameraParams) % kPlacementParams;
    Eigen::Isometry3d& T = m.T_camera_board[p];
    if (j < 3) {
        T.linear() = T.linear() * Eigen::AngleAxisd(h, Eigen::Vector3d::Unit(j)).toRotationMatrix();
    } else if (j < 6) {
        T.translation()(j - 3) += h;
    } else {
        Eigen::Vector3d& a = m.axis[p];
        const Eigen::Vector3d e1 = a.unitOrthogonal();
        a = (a + h * (j == 6 ? e1 : a.cross(e1))).normalized();
    }
}

double perturb_step(int k) {
    if (k < 4) return 1e-3;              // px
    if (k < kCameraParams) return 1e-7;  // distortion terms
    const int j = (k - kCameraParams) % kPlacementParams;
    return j >= 3 && j < 6 ? 1e-5 : 1e-8;  // mm; rad
}

// Reprojection residuals (px) into r, view i at rows 2·corners·i …; only `placement`'s views
// when it is ≥ 0 (the others' rows are left as they are).
void stage_residuals(const StageModel& m, const std::vector<StageObservation>& obs,
                     const std::vector<cv::Point3f>& board, int placement, Eigen::VectorXd& r) {
    const cv::Mat K = camera_matrix(m.camera), D = distortion(m.camera);
    const auto n = static_cast<Eigen::Index>(board.size());
    std::vector<cv::Point3d> cam(board.size());
    std::vector<cv::Point2d> px;
    for (std::size_t i = 0; i < obs.size(); ++i) {
        if (placement >= 0 && obs[i].placement != placement) continue;
        const Eigen::Isometry3d T = board_pose(m, obs[i].placement, obs[i].stage_mm);
        for (std::size_t k = 0; k < board.size(); ++k) {
            const Eigen::Vector3d q = T * Eigen::Vector3d(board[k].x, board[k].y, board[k].z);
            cam[k] = cv::Point3d(q.x(), q.y(), q.z());
        }
        cv::projectPoints(cam, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, D, px);
        const auto row = 2 * n * static_cast<Eigen::Index>(i);
        for (Eigen::Index k = 0; k < n; ++k) {
            r(row + 2 * k) = px[k].x - (*obs[i].corners)[k].x;
            r(row + 2 * k + 1) = px[k].y - (*obs[i].corners)[k].y;
        }
    }
}

// Levenberg–Marquardt on every corner's reprojection, central-difference Jacobian (a placement's
// parameters move only its views). Returns the RMS reprojection error per corner, px.
double refine_on_stage(StageModel& m, const std::vector<StageObservation>& obs,
                       const Checkerboard& b) {
    const std::vector<cv::Point3f> board = board_points(b);
    const int params = kCameraParams + kPlacementParams * static_cast<int>(m.axis.size());
    Eigen::VectorXd r(2 * static_cast<Eigen::Index>(board.size() * obs.size()));
    stage_residuals(m, obs, board, -1, r);
    double cost = r.squaredNorm(), lambda = 1e-3;
    for (int iteration = 0; iteration < 100; ++iteration) {
        Eigen::MatrixXd J(r.size(), params);
        for (int k = 0; k < params; ++k) {
            const double h = perturb_step(k);
            const int p = k < kCameraParams ? -1 : (k - kCameraParams) / kPlacementParams;
            StageModel plus = m, minus = m;
            perturb(plus, k, h);
            perturb(minus, k, -h);
            Eigen::VectorXd rp = r, rm = r;
            stage_residuals(plus, obs, board, p, rp);
            stage_residuals(minus, obs, board, p, rm);
            J.col(k) = (rp - rm) / (2 * h);
        }
        const Eigen::MatrixXd A = J.transpose() * J;
        const Eigen::VectorXd g = J.transpose() * r;
        bool improved = false, settled = false;
        for (int tries = 0; tries < 12 && !improved; ++tries) {
            Eigen::MatrixXd H = A;
            H.diagonal() *= 1.0 + lambda;
            const Eigen::VectorXd d = H.ldlt().solve(-g);
            StageModel next = m;
            for (int k = 0; k < params; ++k) perturb(next, k, d(k));
            Eigen::VectorXd rn = r;
            stage_residuals(next, obs, board, -1, rn);
            if (rn.squaredNorm() < cost) {
                settled = cost - rn.squaredNorm() < 1e-10 * cost;
                m = std::move(next), r = std::move(rn), cost = r.squaredNorm();
                lambda = std::max(lambda / 10, 1e-9), improved = true;
            } else {
                lambda *= 10;
            }
        }
        if (!improved || settled) break;
    }
    return std::sqrt(cost / static_cast<double>(board.size() * obs.size()));
}

// The stage model's start from the planar calibration's poses: per placement the mean rotation,
// and t_i = t0 + s_i·v fitted to its views' translations (v = R·axis; |v| ≠ 1 is the planar
// fit's scale error).
core::Result<StageModel> initial_stage_model(const SensorCalibration& planar,
                                             const std::vector<Eigen::Isometry3d>& T_camera_board,
                                             const std::vector<StageObservation>& obs,
                                             const std::vector<int>& names) {
    StageModel m{planar.camera, {}, {}};
    for (std::size_t p = 0; p < names.size(); ++p) {
        Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
        Eigen::MatrixXd A = Eigen::MatrixXd::Zero(0, 6);
        Eigen::VectorXd y(0);
        double s_min = 1e300, s_max = -1e300;
        for (std::size_t i = 0; i < obs.size(); ++i) {
            if (obs[i].placement != static_cast<int>(p)) continue;
            sum += T_camera_board[i].linear();
            A.conservativeResize(A.rows() + 3, 6);
            y.conservativeResize(y.size() + 3);
            A.bottomRows(3) << Eigen::Matrix3d::Identity(),
                obs[i].stage_mm * Eigen::Matrix3d::Identity();
            y.tail(3) = T_camera_board[i].translation();
            s_min = std::min(s_min, obs[i].stage_mm), s_max = std::max(s_max, obs[i].stage_mm);
        }
        if (!(s_max - s_min > 1.0))
            return core::make_error("sensor calibration on a stage: placement " +
                                    std::to_string(names[p]) +
                                    " needs views at 2 stage readings at least 1 mm apart");
        const Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
        Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
        T.linear() = svd.matrixU() * svd.matrixV().transpose();
        const Eigen::VectorXd x = A.colPivHouseholderQr().solve(y);
        T.translation() = x.head<3>();
        m.T_camera_board.push_back(T);
        m.axis.push_back((T.linear().transpose() * x.tail<3>()).normalized());
    }
    return m;
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
    if (std::abs(c.plane.normal.y()) < 0.05 || std::abs(c.plane.normal.x()) > 0.99)
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
    Views v;
    for (const auto& view : views) v.push_back(&view);
    if (auto ok = check_views(v); !ok) return ok.error();
    auto corners = find_corners(v, b);
    if (!corners) return corners.error();
    std::vector<Eigen::Isometry3d> T_camera_board;
    SensorCalibration out = calibrate_camera(
        *corners, b, cv::Size(views.front().board.width, views.front().board.height),
        T_camera_board);
    if (auto ok = fit_laser_plane(v, T_camera_board, out); !ok) return ok.error();
    return out;
}

core::Result<SensorCalibration> calibrate_sensor_on_stage(const std::vector<StageView>& views,
                                                          const Checkerboard& b) {
    Views v;
    for (const auto& view : views) v.push_back(&view.view);
    if (auto ok = check_views(v); !ok) return ok.error();
    auto corners = find_corners(v, b);
    if (!corners) return corners.error();
    std::vector<Eigen::Isometry3d> T_camera_board;
    const SensorCalibration planar = calibrate_camera(
        *corners, b, cv::Size(v.front()->board.width, v.front()->board.height), T_camera_board);
    std::vector<int> names;  // placement numbers as given → 0 … P − 1
    std::vector<StageObservation> obs;
    for (std::size_t i = 0; i < views.size(); ++i) {
        auto it = std::find(names.begin(), names.end(), views[i].placement);
        if (it == names.end()) it = names.insert(names.end(), views[i].placement);
        obs.push_back({static_cast<int>(it - names.begin()), views[i].stage_mm, &(*corners)[i]});
    }
    auto model = initial_stage_model(planar, T_camera_board, obs, names);
    if (!model) return model.error();
    SensorCalibration out = planar;
    out.reprojection_rms_px = refine_on_stage(*model, obs, b);
    out.camera = model->camera;
    out.placements = static_cast<int>(names.size());
    for (std::size_t i = 0; i < obs.size(); ++i)
        T_camera_board[i] = board_pose(*model, obs[i].placement, obs[i].stage_mm);
    if (auto ok = fit_laser_plane(v, T_camera_board, out); !ok) return ok.error();
    return out;
}

}  // namespace hotgauge::calib
