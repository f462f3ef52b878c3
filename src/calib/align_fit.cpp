// Step 2 of the face alignment: every point on the artifact fitted by Ceres, and the pose's
// covariance from Ceres at the solution (docs/calibration.md "Faces").
#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <glog/logging.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "align_steps.hpp"

namespace hotgauge::calib::detail {
namespace {

// After place_from_balls the face is within about 0.1 mm; a point farther than this from every
// surface is not on the artifact (posts, plate edges, spikes).
constexpr double kFirstGateMm = 1.0;
// A plane carries three numbers of the pose; this many of its points (evenly spread) fix them to
// well under a micrometre, and keep the problem to about 3.5 · 10⁵ residuals per face.
constexpr std::size_t kMaxPlanePoints = 200000;
// Two rounds, the second on the first fit's points within kKeepSigma of its noise; a Cauchy loss
// at kLossSigma of the face's own noise (docs/calibration.md "Faces", not measured).
constexpr int kRounds = 2;
constexpr double kKeepSigma = 5.0;
constexpr double kLossSigma = 3.0;
// Median absolute deviation → σ for normally distributed noise.
constexpr double kMadToSigma = 1.4826;
// Ceres on every point: iterations and tolerances (not measured).
constexpr int kFitMaxIterations = 50;
constexpr double kFitFunctionTolerance = 1e-12;
constexpr double kFitParameterTolerance = 1e-12;
// Threads for Ceres's solve, covariance and Jacobian (not measured).
constexpr int kThreads = 2;

// Signed distance of a point, placed by the pose, from its artifact surface.
struct PointResidual {
    ScanPoint p;
    Eigen::Vector3d anchor;  // sphere centre or a point of the plane
    Eigen::Vector3d normal;  // the plane's normal (unused for a sphere)
    double radius;           // the sphere's radius; < 0 for a plane
    template <typename T>
    bool operator()(const T* q, const T* t, const T* v, T* r) const {
        const T xyz[3] = {T(p.q.x()), T(0), T(p.q.z())};
        T P[3];
        const T wxyz[4] = {q[3], q[0], q[1], q[2]};  // Eigen stores x, y, z, w
        ceres::UnitQuaternionRotatePoint(wxyz, xyz, P);
        for (int k = 0; k < 3; ++k) P[k] += t[k] + T(p.c) * v[k] - T(anchor[k]);
        if (radius < 0.0) {
            r[0] = T(normal.x()) * P[0] + T(normal.y()) * P[1] + T(normal.z()) * P[2];
        } else {
            r[0] = sqrt(P[0] * P[0] + P[1] * P[1] + P[2] * P[2]) - T(radius);
        }
        return true;
    }
};

// Per point its nearest surface within the gate (−1: none) and the distance.
struct Assignment {
    std::vector<int> surface;
    std::vector<double> distance;
};

Assignment assign(const Artifact& a, const std::vector<ScanPoint>& pts, const FacePose& pose,
                  double gate_mm) {
    Assignment as{std::vector<int>(pts.size(), -1), std::vector<double>(pts.size(), 0.0)};
    Eigen::Vector3d n;
    for (std::size_t i = 0; i < pts.size(); ++i) {
        const Eigen::Vector3d p = pose.world(pts[i]);
        double best = gate_mm;
        for (std::size_t j = 0; j < surface_count(a); ++j) {
            const double d = surface_distance(a, j, p, n);
            if (std::abs(d) < std::abs(best)) {
                best = d;
                as.surface[i] = static_cast<int>(j);
            }
        }
        as.distance[i] = best;
    }
    return as;
}

// The assignment a smaller gate would give: a point's nearest surface is the same, or none.
void keep_within(Assignment& as, double gate_mm) {
    for (std::size_t i = 0; i < as.surface.size(); ++i)
        if (!(std::abs(as.distance[i]) < gate_mm)) as.surface[i] = -1;
}

// 1.4826 × the median absolute distance of the assigned points: the noise, robust to outliers.
double robust_sigma(const Assignment& as) {
    std::vector<double> d;
    for (std::size_t i = 0; i < as.surface.size(); ++i)
        if (as.surface[i] >= 0) d.push_back(std::abs(as.distance[i]));
    if (d.empty()) return 0.0;
    auto mid = d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2);
    std::nth_element(d.begin(), mid, d.end());
    return kMadToSigma * *mid;
}

// The points used, per surface: all of a sphere's, a plane's thinned evenly to kMaxPlanePoints.
std::vector<std::size_t> chosen_points(const Artifact& a, const Assignment& as,
                                       std::vector<int>& counts) {
    counts.assign(surface_count(a), 0);
    for (int s : as.surface)
        if (s >= 0) ++counts[s];
    std::vector<std::size_t> stride(counts.size(), 1), seen(counts.size(), 0), out;
    for (std::size_t j = a.spheres.size(); j < counts.size(); ++j)
        stride[j] = std::max<std::size_t>(1, (counts[j] + kMaxPlanePoints - 1) / kMaxPlanePoints);
    for (std::size_t i = 0; i < as.surface.size(); ++i) {
        const int s = as.surface[i];
        if (s >= 0 && seen[s]++ % stride[s] == 0) out.push_back(i);
    }
    std::fill(counts.begin(), counts.end(), 0);
    for (std::size_t i : out) ++counts[as.surface[i]];
    return out;
}

struct Solved {
    std::unique_ptr<ceres::LossFunction> loss;  // not owned by the problem (DO_NOT_TAKE_OWNERSHIP)
    std::unique_ptr<ceres::Problem> problem;
    int iterations = 0;
    double sum2 = 0.0;  // Σ r² at the solution, no loss
    std::size_t m = 0;
};

Solved solve(const Artifact& a, const std::vector<ScanPoint>& pts, const Assignment& as,
             const std::vector<std::size_t>& use, double loss_scale_mm, FacePose& pose) {
    Solved s;
    ceres::Problem::Options po;
    po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    s.loss = std::make_unique<ceres::CauchyLoss>(loss_scale_mm);
    s.problem = std::make_unique<ceres::Problem>(po);
    for (std::size_t i : use) {
        const auto j = static_cast<std::size_t>(as.surface[i]);
        PointResidual r{pts[i], {}, {}, -1.0};
        if (j < a.spheres.size()) {
            r.anchor = a.spheres[j].center_mm;
            r.radius = 0.5 * a.spheres[j].diameter_mm;
        } else {
            r.anchor = a.planes[j - a.spheres.size()].point_mm;
            r.normal = a.planes[j - a.spheres.size()].normal;
        }
        s.problem->AddResidualBlock(
            new ceres::AutoDiffCostFunction<PointResidual, 1, 4, 3, 3>(new PointResidual(r)),
            s.loss.get(), pose.R.coeffs().data(), pose.t.data(), pose.v.data());
    }
    s.problem->SetManifold(pose.R.coeffs().data(), new ceres::EigenQuaternionManifold);
    ceres::Solver::Options opt;
    opt.logging_type = ceres::SILENT;
    opt.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
    opt.max_num_iterations = kFitMaxIterations;
    opt.function_tolerance = kFitFunctionTolerance;
    opt.parameter_tolerance = kFitParameterTolerance;
    opt.num_threads = kThreads;
    ceres::Solver::Summary summary;
    ceres::Solve(opt, s.problem.get(), &summary);
    pose.R.normalize();
    s.iterations = static_cast<int>(summary.iterations.size());
    Eigen::Vector3d n;
    for (std::size_t i : use) {
        const double d =
            surface_distance(a, static_cast<std::size_t>(as.surface[i]), pose.world(pts[i]), n);
        s.sum2 += d * d;
    }
    s.m = use.size();
    return s;
}

// The covariance of (rotation vector, t, v) from ceres::Covariance, scaled by σ². Ceres's
// quaternion tangent is half the rotation vector (Plus: [cos|δ|, sin|δ|·δ/|δ|] ⊗ q).
bool covariance(ceres::Problem& problem, FacePose& pose, double sigma2, Matrix9& C) {
    double* blocks[3] = {pose.R.coeffs().data(), pose.t.data(), pose.v.data()};
    std::vector<std::pair<const double*, const double*>> pairs;
    for (int i = 0; i < 3; ++i)
        for (int j = i; j < 3; ++j) pairs.emplace_back(blocks[i], blocks[j]);
    // A rank-deficient Jacobian is our message (the weak direction), not a glog warning; glog is
    // Ceres's alone in this process.
    FLAGS_minloglevel = google::GLOG_ERROR;
    ceres::Covariance::Options co;
    co.num_threads = kThreads;
    ceres::Covariance cov(co);
    if (!cov.Compute(pairs, &problem)) return false;
    const double scale[3] = {2.0, 1.0, 1.0};
    for (int i = 0; i < 3; ++i)
        for (int j = i; j < 3; ++j) {
            Eigen::Matrix<double, 3, 3, Eigen::RowMajor> b;
            cov.GetCovarianceBlockInTangentSpace(blocks[i], blocks[j], b.data());
            C.block<3, 3>(3 * i, 3 * j) = b * scale[i] * scale[j] * sigma2;
            if (j != i) C.block<3, 3>(3 * j, 3 * i) = C.block<3, 3>(3 * i, 3 * j).transpose();
        }
    return true;
}

// JᵀJ / σ² in the same order as the covariance, from the Jacobian Ceres evaluates (tangent
// space, robustified): what names the weak direction when the covariance does not exist.
Matrix9 information(ceres::Problem& problem, FacePose& pose, double sigma2) {
    ceres::Problem::EvaluateOptions eo;
    eo.parameter_blocks = {pose.R.coeffs().data(), pose.t.data(), pose.v.data()};
    eo.num_threads = kThreads;
    ceres::CRSMatrix J;
    problem.Evaluate(eo, nullptr, nullptr, nullptr, &J);
    Matrix9 H = Matrix9::Zero();
    Eigen::Matrix<double, 9, 1> row;
    for (int r = 0; r < J.num_rows; ++r) {
        row.setZero();
        for (int k = J.rows[r]; k < J.rows[r + 1]; ++k) row(J.cols[k]) = J.values[k];
        row.head<3>() *= 0.5;  // d/dω = d/dδ · dδ/dω, δ = ω/2
        H.selfadjointView<Eigen::Lower>().rankUpdate(row);
    }
    return Matrix9(H.selfadjointView<Eigen::Lower>()) / sigma2;
}

// Per surface the mean and RMS of the used points' distances, and their map over the scan.
void summarize(const Artifact& a, const std::vector<ScanPoint>& pts, const Assignment& as,
               const std::vector<std::size_t>& use, PointFit& out) {
    // The residual map's grid: columns across the scan, rows along it (not measured).
    constexpr int kColumns = 120, kRows = 80;
    const std::size_t n = surface_count(a);
    out.mean_mm.assign(n, 0.0);
    out.rms_surface_mm.assign(n, 0.0);
    ResidualMap& m = out.map;
    m.columns = kColumns;
    m.rows = kRows;
    m.x0_mm = m.c0_mm = std::numeric_limits<double>::infinity();
    m.x1_mm = m.c1_mm = -std::numeric_limits<double>::infinity();
    for (const auto& p : pts) {
        m.x0_mm = std::min(m.x0_mm, p.q.x()), m.x1_mm = std::max(m.x1_mm, p.q.x());
        m.c0_mm = std::min(m.c0_mm, p.c), m.c1_mm = std::max(m.c1_mm, p.c);
    }
    std::vector<double> sum(kColumns * kRows, 0.0);
    std::vector<int> count(kColumns * kRows, 0);
    Eigen::Vector3d normal;
    for (std::size_t i : use) {
        const auto j = static_cast<std::size_t>(as.surface[i]);
        const double d = surface_distance(a, j, out.pose.world(pts[i]), normal);
        out.mean_mm[j] += d;
        out.rms_surface_mm[j] += d * d;
        const auto col = std::min<int>(
            kColumns - 1,
            static_cast<int>((pts[i].q.x() - m.x0_mm) / (m.x1_mm - m.x0_mm + 1e-9) * kColumns));
        const auto row = std::min<int>(
            kRows - 1, static_cast<int>((pts[i].c - m.c0_mm) / (m.c1_mm - m.c0_mm + 1e-9) * kRows));
        sum[row * kColumns + col] += d;
        ++count[row * kColumns + col];
    }
    for (std::size_t j = 0; j < n; ++j)
        if (out.counts[j] > 0) {
            out.mean_mm[j] /= out.counts[j];
            out.rms_surface_mm[j] = std::sqrt(out.rms_surface_mm[j] / out.counts[j]);
        }
    m.mean_mm.assign(sum.size(), std::numeric_limits<float>::quiet_NaN());
    for (std::size_t k = 0; k < sum.size(); ++k)
        if (count[k] > 0) m.mean_mm[k] = static_cast<float>(sum[k] / count[k]);
}

}  // namespace

core::Result<PointFit> fit_points(const Artifact& a, const std::vector<ScanPoint>& pts,
                                  const FacePose& start) {
    PointFit out;
    out.pose = start;
    Assignment as = assign(a, pts, out.pose, kFirstGateMm);
    double sigma = robust_sigma(as);
    Solved s;
    std::vector<std::size_t> use;
    for (int round = 0; round < kRounds; ++round) {
        if (round > 0) {  // the noise measured at the first fit's pose, and its points within 5σ
            as = assign(a, pts, out.pose, kFirstGateMm);
            sigma = robust_sigma(as);
            keep_within(as, std::min(kFirstGateMm, kKeepSigma * sigma));
        }
        if (!(sigma > 0.0)) return core::make_error("no point lies on the artifact's surfaces");
        use = chosen_points(a, as, out.counts);
        s = solve(a, pts, as, use, kLossSigma * sigma, out.pose);
        out.iterations += s.iterations;
    }
    if (s.m <= 9) return core::make_error("fewer than 10 points on the artifact's surfaces");
    out.rms_mm = std::sqrt(s.sum2 / static_cast<double>(s.m));
    const double sigma2 = s.sum2 / static_cast<double>(s.m - 9);
    out.information = information(*s.problem, out.pose, sigma2);
    out.covariance_ok = covariance(*s.problem, out.pose, sigma2, out.covariance);
    summarize(a, pts, as, use, out);
    return out;
}

}  // namespace hotgauge::calib::detail
