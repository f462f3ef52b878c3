#include "hotgauge/calib/hand_eye.hpp"

#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "hotgauge/io/yaml_reader.hpp"

namespace hotgauge::calib {
namespace {

// Two motion axes count as two this far apart (docs/calibration.md: 5°; not measured).
constexpr double kMinAxisSpreadDeg = 5.0;
// A relative motion turning less than this (rad, about 0.06°) has no axis to count (not measured).
constexpr double kMinTurnRad = 1e-3;
// The joint refinement: Gauss–Newton steps at most, done when a step's norm is below
// kRefineStop; forward differences of kRotationStep (rad) and kTranslationStep (mm) (not
// measured).
constexpr int kRefineIterations = 20;
constexpr double kRefineStop = 1e-10;
constexpr double kRotationStep = 1e-7;
constexpr double kTranslationStep = 1e-5;

// Whether the relative motions between poses turn about two directions at least
// kMinAxisSpreadDeg apart (with one direction only, X's translation along it is not determined).
bool motions_turn_about_two_axes(std::span<const HandEyeSample> s) {
    std::vector<Eigen::Vector3d> axes;
    for (std::size_t i = 1; i < s.size(); ++i) {
        const Eigen::AngleAxisd a(
            (s[0].T_base_flange.linear().transpose() * s[i].T_base_flange.linear()));
        if (a.angle() > kMinTurnRad) axes.push_back(a.axis());
    }
    const double min_sin = std::sin(kMinAxisSpreadDeg * M_PI / 180.0);
    for (std::size_t i = 0; i < axes.size(); ++i)
        for (std::size_t j = i + 1; j < axes.size(); ++j)
            if (axes[i].cross(axes[j]).norm() > min_sin) return true;
    return false;
}

// RMS spread of the target's pose in the base frame through every sample.
void residuals(std::span<const HandEyeSample> s, HandEyeSolution& x) {
    std::vector<Eigen::Isometry3d> t;
    Eigen::Vector3d mean_t = Eigen::Vector3d::Zero();
    for (const auto& k : s) {
        t.push_back(k.T_base_flange * x.T_flange_camera * k.T_camera_target);
        mean_t += t.back().translation();
    }
    mean_t /= static_cast<double>(t.size());
    // The mean rotation: the chordal mean (the SVD projection of the summed matrices).
    Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
    for (const auto& p : t) sum += p.linear();
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d mean_r = svd.matrixU() * svd.matrixV().transpose();
    if (mean_r.determinant() < 0) {
        Eigen::Matrix3d flip = Eigen::Matrix3d::Identity();
        flip(2, 2) = -1;
        mean_r = svd.matrixU() * flip * svd.matrixV().transpose();
    }
    double r2 = 0, t2 = 0;
    for (const auto& p : t) {
        const double deg = Eigen::AngleAxisd(mean_r.transpose() * p.linear()).angle() * 180 / M_PI;
        r2 += deg * deg;
        t2 += (p.translation() - mean_t).squaredNorm();
    }
    x.rotation_rms_deg = std::sqrt(r2 / static_cast<double>(t.size()));
    x.translation_rms_mm = std::sqrt(t2 / static_cast<double>(t.size()));
}

Eigen::Isometry3d exp_se3(const Eigen::Matrix<double, 6, 1>& d) {
    Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
    const Eigen::Vector3d w = d.head<3>();
    if (w.norm() > 0) p.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
    p.translation() = d.tail<3>();
    return p;
}

// Per sample: how far T_base_flange·X·T_camera_target is from the target's base pose Z, the
// rotation as a rotation vector times `lever_mm` (its effect at the target's distance) and the
// translation in mm.
Eigen::VectorXd pose_errors(std::span<const HandEyeSample> s, const Eigen::Isometry3d& X,
                            const Eigen::Isometry3d& Z, double lever_mm) {
    Eigen::VectorXd r(6 * static_cast<Eigen::Index>(s.size()));
    for (std::size_t i = 0; i < s.size(); ++i) {
        const Eigen::Isometry3d e = Z.inverse() * s[i].T_base_flange * X * s[i].T_camera_target;
        const Eigen::AngleAxisd a(e.linear());
        const auto k = static_cast<Eigen::Index>(6 * i);
        r.segment<3>(k) = a.axis() * a.angle() * lever_mm;
        r.segment<3>(k + 3) = e.translation();
    }
    return r;
}

// The closed-form X refined jointly with the target's base pose Z by Gauss–Newton on every
// sample's pose error (the closed forms solve rotation first and translation from it, so the
// rotation's error reaches the translation through the robot's lever arms).
Eigen::Isometry3d refine(std::span<const HandEyeSample> s, Eigen::Isometry3d X) {
    double lever = 0;
    for (const auto& k : s) lever += k.T_camera_target.translation().norm();
    lever /= static_cast<double>(s.size());
    Eigen::Isometry3d Z = s[0].T_base_flange * X * s[0].T_camera_target;
    for (int iteration = 0; iteration < kRefineIterations; ++iteration) {
        const Eigen::VectorXd r0 = pose_errors(s, X, Z, lever);
        Eigen::MatrixXd J(r0.size(), 12);
        for (int p = 0; p < 12; ++p) {
            Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
            const double h = p % 6 < 3 ? kRotationStep : kTranslationStep;
            d(p % 6) = h;
            const Eigen::VectorXd r = p < 6 ? pose_errors(s, X * exp_se3(d), Z, lever)
                                            : pose_errors(s, X, Z * exp_se3(d), lever);
            J.col(p) = (r - r0) / h;
        }
        const Eigen::VectorXd step = J.colPivHouseholderQr().solve(-r0);
        X = X * exp_se3(step.head<6>());
        Z = Z * exp_se3(step.tail<6>());
        if (step.norm() < kRefineStop) break;
    }
    return X;
}

cv::Mat to_cv(const Eigen::MatrixXd& m) {
    cv::Mat out;
    cv::eigen2cv(m, out);
    return out;
}

Eigen::Isometry3d isometry(const cv::Mat& r, const cv::Mat& t) {
    Eigen::Matrix3d re;
    Eigen::Vector3d te;
    cv::cv2eigen(r, re);
    cv::cv2eigen(t, te);
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = re;
    T.translation() = te;
    return T;
}

// OpenCV's closed forms: A·X = X·B from the motions between poses (calibrateHandEye: Tsai, Park,
// Daniilidis), then A·X = Z·B with the target's base pose Z from the poses themselves
// (calibrateRobotWorldHandEye: Shah; Li, Wang and Wu).
core::Result<std::vector<HandEyeSolution>> closed_forms(std::span<const HandEyeSample> samples) {
    std::vector<cv::Mat> r_bf, t_bf, r_ct, t_ct, r_fb, t_fb;
    for (const auto& s : samples) {
        const Eigen::Isometry3d T_flange_base = s.T_base_flange.inverse();
        r_bf.push_back(to_cv(s.T_base_flange.linear()));
        t_bf.push_back(to_cv(s.T_base_flange.translation()));
        r_ct.push_back(to_cv(s.T_camera_target.linear()));
        t_ct.push_back(to_cv(s.T_camera_target.translation()));
        r_fb.push_back(to_cv(T_flange_base.linear()));
        t_fb.push_back(to_cv(T_flange_base.translation()));
    }
    std::vector<HandEyeSolution> out;
    const auto add = [&](const std::string& name, const Eigen::Isometry3d& X) {
        HandEyeSolution x{name, X};
        residuals(samples, x);
        out.push_back(x);
    };
    const std::pair<std::string, cv::HandEyeCalibrationMethod> motions[] = {
        {"Tsai", cv::CALIB_HAND_EYE_TSAI},
        {"Park", cv::CALIB_HAND_EYE_PARK},
        {"Daniilidis", cv::CALIB_HAND_EYE_DANIILIDIS}};
    const std::pair<std::string, cv::RobotWorldHandEyeCalibrationMethod> poses[] = {
        {"Shah", cv::CALIB_ROBOT_WORLD_HAND_EYE_SHAH}, {"Li", cv::CALIB_ROBOT_WORLD_HAND_EYE_LI}};
    std::string name;
    try {
        for (const auto& [n, method] : motions) {
            name = n;
            cv::Mat r, t;
            cv::calibrateHandEye(r_bf, t_bf, r_ct, t_ct, r, t, method);
            add(name, isometry(r, t));
        }
        for (const auto& [n, method] : poses) {
            name = n;
            cv::Mat r_tb, t_tb, r_cf, t_cf;
            cv::calibrateRobotWorldHandEye(r_ct, t_ct, r_fb, t_fb, r_tb, t_tb, r_cf, t_cf, method);
            add(name, isometry(r_cf, t_cf).inverse());
        }
    } catch (const cv::Exception& e) {
        return core::make_error("hand-eye (" + name + "): " + e.what());
    }
    return out;
}

}  // namespace

core::Result<std::vector<HandEyeSolution>> solve_hand_eye(std::span<const HandEyeSample> samples) {
    if (samples.size() < 3)
        return core::make_error("hand-eye: too few poses: " + std::to_string(samples.size()) +
                                ", need at least 3");
    if (!motions_turn_about_two_axes(samples))
        return core::make_error(
            "hand-eye: the robot's motions between the " + std::to_string(samples.size()) +
            " poses turn about one direction only: turn the head about two axes at least " +
            std::to_string(static_cast<int>(kMinAxisSpreadDeg)) + "° apart");
    auto out = closed_forms(samples);
    if (!out) return out.error();
    HandEyeSolution best = (*out)[1];  // Park: the refinement's start
    best.method = "Park+refined";
    best.T_flange_camera = refine(samples, best.T_flange_camera);
    residuals(samples, best);
    out->push_back(best);
    return out;
}

core::Result<std::vector<HandEyeSample>> read_hand_eye_poses(const std::filesystem::path& file) {
    const io::YamlReader y(file.string());
    return y.guarded<std::vector<HandEyeSample>>([&] {
        const YAML::Node root = y.load();
        y.expect_map(root, "poses file", {"format", "poses"});
        const std::string format = y.string(y.require(root, "poses file", "format"), "format");
        if (format != "hotgauge-hand-eye-poses-1")
            y.fail(root["format"], "format: '" + format + "', expected hotgauge-hand-eye-poses-1");
        const YAML::Node poses = y.require(root, "poses file", "poses");
        if (!poses.IsSequence()) y.fail(poses, "poses: expected a list");
        std::vector<HandEyeSample> out;
        for (std::size_t i = 0; i < poses.size(); ++i) {
            const std::string w = "poses[" + std::to_string(i) + "]";
            y.expect_map(poses[i], w, {"base_from_flange", "camera_from_target"});
            out.push_back(
                {y.isometry(y.require(poses[i], w, "base_from_flange"), w + ".base_from_flange"),
                 y.isometry(y.require(poses[i], w, "camera_from_target"),
                            w + ".camera_from_target")});
        }
        return out;
    });
}

}  // namespace hotgauge::calib
