#include "hotgauge/sim/target.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <opencv2/calib3d.hpp>

namespace hotgauge::sim {
namespace {

constexpr int kSamples = 1;  // per pixel and axis: board edges are blurred analytically
constexpr double kDeg = std::numbers::pi / 180.0;

}  // namespace

VirtualSensorCamera design_sensor_camera(const SensorConfig& s) {
    VirtualSensorCamera h;
    const Eigen::Vector3d C = s.imager_mm();  // laser frame
    const Eigen::Vector3d aim(0.0, 0.0, 0.5 * (s.min_range_mm + s.max_range_mm));
    const Eigen::Vector3d z = (aim - C).normalized();
    const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
    const Eigen::Vector3d y = z.cross(x);
    Eigen::Matrix3d R_laser_camera;
    R_laser_camera << x, y, z;
    h.T_laser_camera.linear() = R_laser_camera;
    h.T_laser_camera.translation() = C;
    calib::PinholeCamera& c = h.camera;
    c.width = 2048;
    c.height = 1088;
    const double half_width = 0.5 * (s.width - 1) * s.pitch_mm * (aim - C).norm() / s.standoff_mm;
    c.fx = 0.5 * c.width * (aim - C).norm() / std::max(half_width, 1.0) * 0.97;
    c.fy = c.fx * 1.0002;
    c.cx = 0.5 * (c.width - 1) + 3.7;
    c.cy = 0.5 * (c.height - 1) - 2.9;
    c.distortion = {-0.06, 0.03, 2e-4, -1e-4, 0.0};
    // The laser plane y_laser = 0 in the camera frame.
    const Eigen::Isometry3d T_camera_laser = h.T_laser_camera.inverse();
    h.plane.normal = T_camera_laser.linear() * Eigen::Vector3d::UnitY();
    h.plane.offset_mm = h.plane.normal.dot(T_camera_laser.translation());
    if (h.plane.offset_mm < 0) h.plane.normal *= -1.0, h.plane.offset_mm *= -1.0;
    return h;
}

namespace {

// A board centred at `centre` (camera frame) facing the camera, then tilted by up to
// `max_tilt_deg` about a random axis in the board and spun by up to ±20°.
Eigen::Matrix3d board_rotation(const Eigen::Vector3d& centre, double max_tilt_deg,
                               std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    Eigen::Matrix3d R;
    const Eigen::Vector3d nz = centre.normalized();  // board z away from the camera
    const Eigen::Vector3d nx = Eigen::Vector3d::UnitX().cross(nz).cross(nz).normalized() * -1.0;
    R << nx, nz.cross(nx), nz;
    const double axis = 2 * std::numbers::pi * u01(rng);
    return R *
           Eigen::AngleAxisd(max_tilt_deg * kDeg * u01(rng),
                             Eigen::Vector3d(std::cos(axis), std::sin(axis), 0))
               .toRotationMatrix() *
           Eigen::AngleAxisd(20 * kDeg * (2 * u01(rng) - 1), Eigen::Vector3d::UnitZ());
}

// Whether every corner of the board at T, with a square's margin, images 10 px inside.
bool board_in_image(const VirtualSensorCamera& h, const calib::Checkerboard& b,
                    const Eigen::Isometry3d& T) {
    const calib::PinholeCamera& c = h.camera;
    const cv::Mat K = (cv::Mat_<double>(3, 3) << c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
    const cv::Mat D(1, 5, CV_64F, const_cast<double*>(c.distortion.data()));
    std::vector<cv::Point3d> cam;
    for (int j = -1; j <= b.rows; j += b.rows + 1)
        for (int i = -1; i <= b.cols; i += b.cols + 1) {
            const Eigen::Vector3d q = T * Eigen::Vector3d(i * b.square_mm, j * b.square_mm, 0);
            if (q.z() <= 0) return false;
            cam.emplace_back(q.x(), q.y(), q.z());
        }
    std::vector<cv::Point2d> px;
    cv::projectPoints(cam, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, D, px);
    return std::all_of(px.begin(), px.end(), [&](const cv::Point2d& p) {
        return p.x > 10 && p.y > 10 && p.x < c.width - 10 && p.y < c.height - 10;
    });
}

Eigen::Vector3d board_half(const calib::Checkerboard& b) {
    return {(b.cols - 1) * b.square_mm / 2, (b.rows - 1) * b.square_mm / 2, 0};
}

}  // namespace

std::vector<Eigen::Isometry3d> target_poses(const VirtualSensorCamera& h,
                                            const calib::Checkerboard& b, int n,
                                            std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::vector<Eigen::Isometry3d> poses;
    for (int tries = 0; static_cast<int>(poses.size()) < n && tries < 100 * n; ++tries) {
        // Centre on the laser plane, laser frame: x ±110 mm, range 680–1120 mm.
        const Eigen::Vector3d centre_laser(220.0 * (u01(rng) - 0.5), 0.0, 680.0 + 440.0 * u01(rng));
        const Eigen::Vector3d centre = h.T_laser_camera.inverse() * centre_laser;
        Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
        T.linear() = board_rotation(centre, 55.0, rng);
        T.translation() = centre - T.linear() * board_half(b);
        if (board_in_image(h, b, T)) poses.push_back(T);
    }
    return poses;
}

TargetRenderer::TargetRenderer(const calib::PinholeCamera& c, RenderOptions options)
    : camera_(c), options_(options) {
    std::vector<cv::Point2f> px;
    px.reserve(static_cast<std::size_t>(c.width) * c.height * kSamples * kSamples);
    for (int v = 0; v < c.height; ++v)
        for (int u = 0; u < c.width; ++u)
            for (int sv = 0; sv < kSamples; ++sv)
                for (int su = 0; su < kSamples; ++su)
                    px.emplace_back(static_cast<float>(u - 0.5 + (su + 0.5) / kSamples),
                                    static_cast<float>(v - 0.5 + (sv + 0.5) / kSamples));
    const cv::Mat K = (cv::Mat_<double>(3, 3) << c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
    const cv::Mat D(1, 5, CV_64F, const_cast<double*>(c.distortion.data()));
    std::vector<cv::Point2f> out;
    cv::undistortPoints(
        px, out, K, D, cv::noArray(), cv::noArray(),
        cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 1e-10));
    rays_.resize(out.size() * 2);
    std::memcpy(rays_.data(), out.data(), rays_.size() * sizeof(float));
}

template <class Shade>
calib::GrayImage TargetRenderer::render(const Eigen::Isometry3d& T, Shade shade,
                                        std::mt19937_64& rng) const {
    calib::GrayImage img;
    img.width = camera_.width;
    img.height = camera_.height;
    img.pixels.resize(static_cast<std::size_t>(img.width) * img.height);
    const Eigen::Vector3d n = T.linear().col(2), o = T.translation();
    const double n_o = n.dot(o);
    const Eigen::Isometry3d T_board_camera = T.inverse();
    std::normal_distribution<double> noise(0.0, 1.0);
    constexpr int kS2 = kSamples * kSamples;
    for (std::size_t p = 0; p < img.pixels.size(); ++p) {
        double sum = 0.0;
        for (int s = 0; s < kS2; ++s) {
            const std::size_t k = (p * kS2 + static_cast<std::size_t>(s)) * 2;
            const Eigen::Vector3d d(rays_[k], rays_[k + 1], 1.0);
            const double t = n_o / n.dot(d);
            const Eigen::Vector3d X = t * d;
            sum += t > 0 ? shade(X, T_board_camera * X) : 80.0;
        }
        img.pixels[p] = static_cast<std::uint8_t>(
            std::clamp(std::lround(sum / kS2 + options_.noise_dn * noise(rng)), 0L, 255L));
    }
    return img;
}

calib::GrayImage TargetRenderer::board(const calib::Checkerboard& b, const Eigen::Isometry3d& T,
                                       std::mt19937_64& rng) const {
    const double s = b.square_mm;
    return render(
        T,
        [&](const Eigen::Vector3d& X, const Eigen::Vector3d& q) {
            // Squares from −s to cols·s (rows alike), a white border of half a square around.
            if (q.x() < -1.5 * s || q.y() < -1.5 * s || q.x() > (b.cols + 0.5) * s ||
                q.y() > (b.rows + 0.5) * s)
                return 80.0;
            if (q.x() < -s || q.y() < -s || q.x() > b.cols * s || q.y() > b.rows * s) return 220.0;
            // The checker is w(x)·w(y), w = +1 on even squares, −1 on odd; blurred by a Gaussian
            // it is blur(w)(x)·blur(w)(y), and near an edge blur(w) is erf of the signed
            // distance: the edges (and corners) stay exactly where they are.
            const double sigma_mm = options_.blur_px * X.z() / camera_.fx;
            auto wave = [&](double c) {
                const long k = std::lround(c / s);  // the nearest edge, k·s; square k right of it
                const double right = k % 2 == 0 ? 1.0 : -1.0;
                return right *
                       std::erf((c - static_cast<double>(k) * s) / (std::sqrt(2.0) * sigma_mm));
            };
            return 125.0 - 95.0 * wave(q.x()) * wave(q.y());  // w·w = +1: black
        },
        rng);
}

calib::GrayImage TargetRenderer::laser(const calib::Checkerboard& b, const Eigen::Isometry3d& T,
                                       const calib::LaserPlane& plane, std::mt19937_64& rng) const {
    const double s = b.square_mm;
    constexpr double kSigmaMm = 0.25;
    return render(
        T,
        [&](const Eigen::Vector3d& X, const Eigen::Vector3d& q) {
            if (q.x() < -1.5 * s || q.y() < -1.5 * s || q.x() > (b.cols + 0.5) * s ||
                q.y() > (b.rows + 0.5) * s)
                return 5.0;
            const double d = (plane.normal.dot(X) - plane.offset_mm) / kSigmaMm;
            return 10.0 + 230.0 * std::exp(-0.5 * d * d);
        },
        rng);
}

StagePlan default_stage_plan(const SensorConfig& sensor) {
    StagePlan p;
    // The head's first rows see 625 mm: the stage starts inside what every column images.
    const double lo = sensor.min_range_mm + 40.0, hi = sensor.max_range_mm - 20.0;
    for (int i = 0; i < 25; ++i) p.level_mm.push_back(lo + (hi - lo) * i / 24.0);
    for (int i = 0; i < 7; ++i) p.tilted_mm.push_back(lo + 30.0 + (hi - lo - 60.0) * i / 6.0);
    return p;
}

std::vector<calib::StageReading> stage_readings(const VirtualSensorCamera& head,
                                                const StagePlan& plan, std::uint64_t seed,
                                                RenderOptions options) {
    // The plate: 900 × 100 mm, blank (a board whose squares the laser image does not show),
    // centred on the laser frame's z axis, turned about the laser plane's normal (y).
    const calib::Checkerboard plate{90, 10, 10.0};
    const TargetRenderer renderer(head.camera, options);
    std::mt19937_64 rng(seed);
    std::vector<calib::StageReading> out;
    auto take = [&](double height, double tilt_deg) {
        const double a = tilt_deg * std::numbers::pi / 180.0;
        Eigen::Isometry3d T_laser_plate = Eigen::Isometry3d::Identity();
        const Eigen::Vector3d along(std::cos(a), 0.0, std::sin(a)),
            across = Eigen::Vector3d::UnitY();
        T_laser_plate.linear() << along, across, along.cross(across);
        T_laser_plate.translation() = Eigen::Vector3d(0.0, 0.0, height) -
                                      0.5 * plate.cols * plate.square_mm * along -
                                      0.5 * plate.rows * plate.square_mm * across;
        const Eigen::Isometry3d T_camera_plate = head.T_laser_camera.inverse() * T_laser_plate;
        out.push_back({renderer.laser(plate, T_camera_plate, head.plane, rng), height, tilt_deg});
    };
    for (double h : plan.level_mm) take(h, 0.0);
    for (double h : plan.tilted_mm) {
        take(h, plan.tilt_deg);
        take(h, -plan.tilt_deg);
    }
    return out;
}

}  // namespace hotgauge::sim
