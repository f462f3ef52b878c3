// Least-squares planes and circles (docs/fitting.md). Every fit works on data centred on its
// centroid: NIST cases sit hundreds of mm from the origin, and centring keeps the 3x3 scatter and
// the circle moments well conditioned. No allocation inside per-point loops.
#include "hotgauge/measure/fit.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <utility>

namespace hotgauge::measure {
namespace {

// A scatter whose second principal spread is below this share of the largest (the circle's 2x2
// determinant against scale⁴, the plane's eigenvalues) is collinear: rounding, not a spread
// (not measured).
constexpr double kCollinearRel = 1e-12;
// Newton steps on Taubin's characteristic polynomial at most; it stops sooner when a step no
// longer decreases it (not measured).
constexpr int kTaubinNewtonSteps = 100;

double sq(double x) { return x * x; }

template <class Vec>
bool all_finite(std::span<const Vec> points) {
    for (const auto& p : points)
        if (!p.allFinite()) return false;
    return true;
}

template <class Vec>
Vec centroid(std::span<const Vec> points) {
    Vec sum = Vec::Zero();
    for (const auto& p : points) sum += p;
    return sum / static_cast<double>(points.size());
}

// Geometric residual sum of squares, gradient-side sums JᵀJ and Jᵀr of the circle |p − c| − r
// in centred coordinates. Row of J: [−(x−a)/d, −(y−b)/d, −1] (∂/∂a, ∂/∂b, ∂/∂r).
struct CircleNormal {
    Eigen::Matrix3d jtj = Eigen::Matrix3d::Zero();
    Eigen::Vector3d jtr = Eigen::Vector3d::Zero();
    double ssr = 0.0;
};

double circle_ssr(std::span<const Eigen::Vector2d> points, const Eigen::Vector2d& mean,
                  const Eigen::Vector3d& p) {
    double ssr = 0.0;
    for (const auto& q : points) {
        const double res =
            std::sqrt(sq(q.x() - mean.x() - p[0]) + sq(q.y() - mean.y() - p[1])) - p[2];
        ssr += res * res;
    }
    return ssr;
}

CircleNormal circle_normal(std::span<const Eigen::Vector2d> points, const Eigen::Vector2d& mean,
                           const Eigen::Vector3d& p) {
    // Plain scalar sums of the 6 distinct JᵀJ entries: no Eigen temporaries per point.
    double saa = 0, sab = 0, sbb = 0, sa = 0, sb = 0, sea = 0, seb = 0, se = 0, ssr = 0;
    for (const auto& q : points) {
        const double dx = q.x() - mean.x() - p[0], dy = q.y() - mean.y() - p[1];
        const double d = std::sqrt(dx * dx + dy * dy);
        // A point exactly on the centre has no defined direction; it still constrains r.
        const double ja = d > 0.0 ? -dx / d : 0.0, jb = d > 0.0 ? -dy / d : 0.0;  // jr = −1
        const double e = d - p[2];
        saa += ja * ja;
        sab += ja * jb;
        sbb += jb * jb;
        sa += ja;
        sb += jb;
        sea += ja * e;
        seb += jb * e;
        se += e;
        ssr += e * e;
    }
    const double n = static_cast<double>(points.size());
    CircleNormal ne;
    ne.jtj << saa, sab, -sa, sab, sbb, -sb, -sa, -sb, n;
    ne.jtr << sea, seb, -se;
    ne.ssr = ssr;
    return ne;
}

// Taubin (1991) on centred data, in Chernov's Newton formulation (N. Chernov, "Circular and Linear
// Regression", CRC 2010, and his CircleFitByTaubin code): the smallest root of the characteristic
// polynomial, found by Newton from 0. Returns centre relative to `mean` and radius, or an Error.
struct Taubin {
    Eigen::Vector2d center;  // relative to the centroid
    double radius;
};

core::Result<Taubin> taubin(std::span<const Eigen::Vector2d> points, const Eigen::Vector2d& mean) {
    const double n = static_cast<double>(points.size());
    // Scale to unit RMS distance from the centroid: keeps the quartic moments near 1.
    double mxx = 0, myy = 0, mxy = 0;
    for (const auto& q : points) {
        const double x = q.x() - mean.x(), y = q.y() - mean.y();
        mxx += x * x;
        myy += y * y;
        mxy += x * y;
    }
    mxx /= n;
    myy /= n;
    mxy /= n;
    const double scale2 = mxx + myy;
    if (!(scale2 > 0.0)) return core::make_error("circle fit: all points coincide");
    // Collinear points: the 2x2 scatter is rank 1 and the algebraic system is singular.
    if (mxx * myy - mxy * mxy <= kCollinearRel * scale2 * scale2)
        return core::make_error("circle fit: points are collinear");
    const double s = std::sqrt(scale2);
    mxx = 0, myy = 0, mxy = 0;
    double mxz = 0, myz = 0, mzz = 0;
    for (const auto& q : points) {
        const double x = (q.x() - mean.x()) / s, y = (q.y() - mean.y()) / s;
        const double z = x * x + y * y;
        mxx += x * x;
        myy += y * y;
        mxy += x * y;
        mxz += x * z;
        myz += y * z;
        mzz += z * z;
    }
    mxx /= n, myy /= n, mxy /= n, mxz /= n, myz /= n, mzz /= n;
    const double mz = mxx + myy;
    const double cov_xy = mxx * myy - mxy * mxy;
    const double var_z = mzz - mz * mz;
    const double a3 = 4.0 * mz;
    const double a2 = -3.0 * mz * mz - mzz;
    const double a1 = var_z * mz + 4.0 * cov_xy * mz - mxz * mxz - myz * myz;
    const double a0 =
        mxz * (mxz * myy - myz * mxy) + myz * (myz * mxx - mxz * mxy) - var_z * cov_xy;
    double x = 0.0, y = a0;
    for (int it = 0; it < kTaubinNewtonSteps; ++it) {
        const double dy = a1 + x * (2.0 * a2 + 3.0 * a3 * x);
        const double x_new = x - y / dy;
        if (x_new == x || !std::isfinite(x_new)) break;
        const double y_new = a0 + x_new * (a1 + x_new * (a2 + x_new * a3));
        if (std::abs(y_new) >= std::abs(y)) break;
        x = x_new;
        y = y_new;
    }
    const double det = x * x - x * mz + cov_xy;
    const double cx = (mxz * (myy - x) - myz * mxy) / det / 2.0;
    const double cy = (myz * (mxx - x) - mxz * mxy) / det / 2.0;
    const double r = std::sqrt(cx * cx + cy * cy + mz);
    if (!std::isfinite(cx) || !std::isfinite(cy) || !std::isfinite(r) || !(r > 0.0))
        return core::make_error("circle fit: algebraic fit is singular (points nearly collinear)");
    return Taubin{Eigen::Vector2d(cx, cy) * s, r * s};
}

core::Result<void> check_circle_input(std::span<const Eigen::Vector2d> points) {
    if (points.size() < 3)
        return core::make_error("circle fit: need at least 3 points, got " +
                                std::to_string(points.size()));
    if (!all_finite(points)) return core::make_error("circle fit: non-finite coordinates");
    return {};
}

// Iterative rejection shared by the plane and circle (header: RejectOptions). `fit` fits a
// subset, `residual` gives a point's residual to a fit.
template <class Vec, class Fit, class FitFn, class ResidualFn>
core::Result<std::pair<Fit, std::vector<std::uint8_t>>> reject(std::span<const Vec> points,
                                                               const RejectOptions& options,
                                                               FitFn fit_fn, ResidualFn residual) {
    std::vector<std::uint8_t> inlier(points.size(), 1);
    auto fit = fit_fn(points);
    if (!fit) return fit.error();
    std::vector<Vec> subset;
    subset.reserve(points.size());
    std::vector<std::uint8_t> next(points.size());
    for (int round = 0; round < options.max_rounds; ++round) {
        const double threshold = std::max(options.k_sigma * fit->rms_mm, options.min_threshold_mm);
        std::size_t count = 0;
        for (std::size_t i = 0; i < points.size(); ++i) {
            next[i] = std::abs(residual(*fit, points[i])) <= threshold ? 1 : 0;
            count += next[i];
        }
        if (next == inlier) break;
        if (count < 3)
            return core::make_error("robust fit: fewer than 3 inliers remain (" +
                                    std::to_string(count) + " of " + std::to_string(points.size()) +
                                    ")");
        inlier.swap(next);
        subset.clear();
        for (std::size_t i = 0; i < points.size(); ++i)
            if (inlier[i]) subset.push_back(points[i]);
        fit = fit_fn(std::span<const Vec>(subset));
        if (!fit) return fit.error();
    }
    return std::pair<Fit, std::vector<std::uint8_t>>{std::move(*fit), std::move(inlier)};
}

double circle_residual(const CircleFit& c, const Eigen::Vector2d& p) {
    return (p - c.center).norm() - c.radius;
}

// Levenberg–Marquardt with Marquardt's diagonal scaling on (a, b, r), centred coordinates: moves
// p from the Taubin seed to the geometric circle, ne kept its normal equations at p.
struct CircleIterations {
    int iterations = 0;
    bool converged = false;
};
CircleIterations iterate_circle(std::span<const Eigen::Vector2d> points,
                                const Eigen::Vector2d& mean, Eigen::Vector3d& p, CircleNormal& ne) {
    constexpr int kMaxIterations = 100;
    // Marquardt's damping: starts near Gauss–Newton, ×/÷ 10 per rejected/accepted step; beyond
    // kLambdaMax no step descends.
    constexpr double kLambdaStart = 1e-3, kLambdaFactor = 10.0;
    constexpr double kLambdaMin = 1e-12, kLambdaMax = 1e12;
    // Relative steps: below kGaussNewtonRel the plain Gauss–Newton steps, converged at
    // kConvergedRel or when they stop shrinking below kRoundingFloorRel (see below).
    constexpr double kGaussNewtonRel = 1e-6, kConvergedRel = 1e-12, kRoundingFloorRel = 1e-10;
    double lambda = kLambdaStart;
    double prev_rel = std::numeric_limits<double>::infinity();
    bool converged = false;
    int it = 0;
    while (it < kMaxIterations && !converged) {
        ++it;
        const Eigen::Vector3d gn = ne.jtj.ldlt().solve(-ne.jtr);  // undamped Gauss–Newton step
        if (!gn.allFinite()) break;
        const double rel = gn.norm() / p.norm();
        if (rel < kGaussNewtonRel) {
            // Close to the minimum the change of SSR (~rel²) is below its rounding, so LM's
            // accept/reject test is noise: take plain Gauss–Newton steps. Converged when the step
            // is < 1e-12 relative, or when it stops shrinking below 1e-10 (rounding floor).
            converged = rel <= kConvergedRel || (rel < kRoundingFloorRel && rel > 0.5 * prev_rel);
            prev_rel = rel;
            p += gn;
            ne = circle_normal(points, mean, p);
            continue;
        }
        // Levenberg–Marquardt with Marquardt's diagonal scaling.
        Eigen::Matrix3d a = ne.jtj;
        a.diagonal() += lambda * ne.jtj.diagonal();
        const Eigen::Vector3d step = a.ldlt().solve(-ne.jtr);
        if (!step.allFinite()) break;
        const Eigen::Vector3d trial = p + step;
        if (const double ssr = circle_ssr(points, mean, trial); ssr < ne.ssr) {
            p = trial;
            ne = circle_normal(points, mean, p);
            lambda = std::max(lambda / kLambdaFactor, kLambdaMin);
        } else if ((lambda *= kLambdaFactor) > kLambdaMax) {
            break;  // no descent although far from a stationary point
        }
    }
    return {it, converged};
}

// Covariance of the parameters: s² (JᵀJ)⁻¹ with s² = SSR / (n − 3), n > 3.
void add_circle_uncertainty(const CircleNormal& ne, std::size_t n, CircleFit& f) {
    const double s2 = ne.ssr / static_cast<double>(n - 3);
    const Eigen::Matrix3d cov = s2 * ne.jtj.inverse();
    if (!cov.allFinite()) return;
    f.u_radius_mm = std::sqrt(std::max(cov(2, 2), 0.0));
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> ce(cov.topLeftCorner<2, 2>());
    f.u_center_mm = std::sqrt(std::max(ce.eigenvalues()[1], 0.0));
}

// The best of `options.iterations` planes through 3 random points: the most points within
// threshold_mm (RANSAC's consensus). count 0: every sample was collinear.
struct PlaneHypothesis {
    std::size_t count = 0;
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
    Eigen::Vector3d point;
};
PlaneHypothesis best_sampled_plane(std::span<const Eigen::Vector3d> points,
                                   const Eigen::Vector3d& c, const RansacOptions& options) {
    // A cross product below 1e-12 of the extent² is rounding, not a normal.
    constexpr double kCollinearRel2 = 1e-24;
    const std::size_t n = points.size();
    double extent2 = 0.0;
    for (const auto& p : points) extent2 = std::max(extent2, (p - c).squaredNorm());
    std::mt19937_64 rng(options.seed);
    // Plain modulo draw: its bias is < n / 2^64 and, unlike std::uniform_int_distribution, it
    // gives the same samples with every standard library.
    auto draw = [&] { return static_cast<std::size_t>(rng() % n); };
    PlaneHypothesis best;
    best.point = c;
    for (int it = 0; it < options.iterations; ++it) {
        const std::size_t i = draw();
        std::size_t j = draw(), k = draw();
        while (j == i) j = draw();
        while (k == i || k == j) k = draw();
        const Eigen::Vector3d nrm = (points[j] - points[i]).cross(points[k] - points[i]);
        // Skip (nearly) collinear samples: their normal is noise.
        if (!(nrm.squaredNorm() > kCollinearRel2 * extent2 * extent2)) continue;
        const Eigen::Vector3d unit = nrm.normalized();
        const double offset = unit.dot(points[i]);
        // Counted in blocks; a plane that can no longer beat the best even if every point left
        // were its inlier is dropped (the same best plane, most of the counting saved).
        constexpr std::size_t kBlock = 512;
        std::size_t count = 0;
        for (std::size_t b = 0; b < n && count + (n - b) > best.count; b += kBlock)
            for (std::size_t q = b; q < std::min(n, b + kBlock); ++q)
                count += std::abs(unit.dot(points[q]) - offset) <= options.threshold_mm;
        if (count > best.count) best = {count, unit, points[i]};
    }
    return best;
}

// The points within threshold_mm of the plane (normal, point) into `subset`, their indices in
// `points` into `index` (subset[s] == points[index[s]]).
void collect_consensus(std::span<const Eigen::Vector3d> points, const Eigen::Vector3d& normal,
                       const Eigen::Vector3d& point, double threshold_mm,
                       std::vector<Eigen::Vector3d>& subset, std::vector<std::size_t>& index) {
    subset.clear();
    index.clear();
    for (std::size_t i = 0; i < points.size(); ++i) {
        if (std::abs(normal.dot(points[i] - point)) > threshold_mm) continue;
        subset.push_back(points[i]);
        index.push_back(i);
    }
}

}  // namespace

core::Result<PlaneFit> fit_plane(std::span<const Eigen::Vector3d> points) {
    if (points.size() < 3)
        return core::make_error("plane fit: need at least 3 points, got " +
                                std::to_string(points.size()));
    if (!all_finite(points)) return core::make_error("plane fit: non-finite coordinates");
    const Eigen::Vector3d c = centroid(points);
    Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
    for (const auto& p : points) {
        const Eigen::Vector3d d = p - c;
        scatter.noalias() += d * d.transpose();
    }
    // Iterative (QR) solver rather than computeDirect: the closed-form 3x3 path loses digits in
    // the smallest eigenvector, which is exactly the one we want.
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);
    if (eig.info() != Eigen::Success) return core::make_error("plane fit: eigen solver failed");
    const Eigen::Vector3d lambda = eig.eigenvalues();  // ascending
    if (!(lambda[2] > 0.0)) return core::make_error("plane fit: all points coincide");
    if (lambda[1] <= kCollinearRel * lambda[2])
        return core::make_error("plane fit: points are collinear");
    PlaneFit f;
    f.point = c;
    f.normal = eig.eigenvectors().col(0).normalized();
    // Deterministic sign: the largest-magnitude component is positive.
    Eigen::Index k = 0;
    f.normal.cwiseAbs().maxCoeff(&k);
    if (f.normal[k] < 0.0) f.normal = -f.normal;
    double ssr = 0.0;
    for (const auto& p : points) {
        const double d = f.normal.dot(p - c);
        ssr += d * d;
    }
    f.n_points = static_cast<std::int64_t>(points.size());
    f.rms_mm = std::sqrt(ssr / static_cast<double>(points.size()));
    return f;
}

core::Result<CircleFit> fit_circle_algebraic(std::span<const Eigen::Vector2d> points) {
    if (auto ok = check_circle_input(points); !ok) return ok.error();
    const Eigen::Vector2d mean = centroid(points);
    auto t = taubin(points, mean);
    if (!t) return t.error();
    CircleFit f;
    f.center = mean + t->center;
    f.radius = t->radius;
    f.n_points = static_cast<std::int64_t>(points.size());
    f.rms_mm = std::sqrt(
        circle_ssr(points, mean, Eigen::Vector3d(t->center.x(), t->center.y(), t->radius)) /
        static_cast<double>(points.size()));
    return f;
}

core::Result<CircleFit> fit_circle(std::span<const Eigen::Vector2d> points) {
    if (auto ok = check_circle_input(points); !ok) return ok.error();
    const Eigen::Vector2d mean = centroid(points);
    auto seed = taubin(points, mean);
    if (!seed) return seed.error();
    Eigen::Vector3d p(seed->center.x(), seed->center.y(), seed->radius);
    CircleNormal ne = circle_normal(points, mean, p);
    const CircleIterations lm = iterate_circle(points, mean, p, ne);
    if (!lm.converged || !p.allFinite() || !(p[2] > 0.0))
        return core::make_error("circle fit: Levenberg-Marquardt did not converge in " +
                                std::to_string(lm.iterations) + " iterations");
    CircleFit f;
    f.center = mean + p.head<2>();
    f.radius = p[2];
    f.iterations = lm.iterations;
    const std::size_t n = points.size();
    f.n_points = static_cast<std::int64_t>(n);
    f.rms_mm = std::sqrt(ne.ssr / static_cast<double>(n));
    if (n > 3) add_circle_uncertainty(ne, n, f);
    return f;
}

core::Result<Circle3dFit> fit_circle3d(std::span<const Eigen::Vector3d> points) {
    auto plane = fit_plane(points);
    if (!plane) return core::make_error("circle3d " + plane.error().message);
    const Eigen::Vector3d u = plane->normal.unitOrthogonal();
    const Eigen::Vector3d v = plane->normal.cross(u);
    std::vector<Eigen::Vector2d> in_plane;
    in_plane.reserve(points.size());
    for (const auto& p : points) {
        const Eigen::Vector3d d = p - plane->point;
        in_plane.emplace_back(d.dot(u), d.dot(v));
    }
    auto c = fit_circle(in_plane);
    if (!c) return core::make_error("circle3d " + c.error().message);
    Circle3dFit f;
    f.center = plane->point + c->center.x() * u + c->center.y() * v;
    f.axis = plane->normal;
    f.radius = c->radius;
    f.rms_mm = c->rms_mm;
    f.n_points = c->n_points;
    return f;
}

core::Result<RobustPlaneFit> fit_plane_robust(std::span<const Eigen::Vector3d> points,
                                              const RejectOptions& options) {
    auto r = reject<Eigen::Vector3d, PlaneFit>(
        points, options, [](std::span<const Eigen::Vector3d> s) { return fit_plane(s); },
        [](const PlaneFit& f, const Eigen::Vector3d& p) { return f.distance(p); });
    if (!r) return r.error();
    return RobustPlaneFit{std::move(r->first), std::move(r->second)};
}

core::Result<RobustCircleFit> fit_circle_robust(std::span<const Eigen::Vector2d> points,
                                                const RejectOptions& options) {
    auto r = reject<Eigen::Vector2d, CircleFit>(
        points, options, [](std::span<const Eigen::Vector2d> s) { return fit_circle(s); },
        circle_residual);
    if (!r) return r.error();
    return RobustCircleFit{std::move(r->first), std::move(r->second)};
}

core::Result<RobustPlaneFit> ransac_plane(std::span<const Eigen::Vector3d> points,
                                          const RansacOptions& options) {
    const std::size_t n = points.size();
    if (n < 3)
        return core::make_error("ransac plane: need at least 3 points, got " + std::to_string(n));
    if (!all_finite(points)) return core::make_error("ransac plane: non-finite coordinates");
    if (!(options.threshold_mm > 0.0))
        return core::make_error("ransac plane: threshold_mm must be positive");
    const PlaneHypothesis best = best_sampled_plane(points, centroid(points), options);
    if (best.count < 3)
        return core::make_error("ransac plane: no plane with 3 or more inliers in " +
                                std::to_string(options.iterations) + " iterations");
    // Refine: least squares on the consensus set, re-collect the consensus of the refined plane
    // (a 3-point model is tilted by its noise), then iterative rejection on that set.
    std::vector<Eigen::Vector3d> subset;
    std::vector<std::size_t> index;  // subset[s] == points[index[s]]
    subset.reserve(n);
    index.reserve(n);
    collect_consensus(points, best.normal, best.point, options.threshold_mm, subset, index);
    auto ls = fit_plane(subset);
    if (!ls) return core::make_error("ransac plane: " + ls.error().message);
    collect_consensus(points, ls->normal, ls->point, options.threshold_mm, subset, index);
    auto robust = fit_plane_robust(subset);
    if (!robust) return core::make_error("ransac plane: " + robust.error().message);
    RobustPlaneFit out;
    out.fit = robust->fit;
    out.inlier.assign(n, 0);
    for (std::size_t s = 0; s < index.size(); ++s) out.inlier[index[s]] = robust->inlier[s];
    return out;
}

core::Result<double> between_std(std::span<const double> v, std::span<const double> u) {
    if (v.size() < 2 || u.size() != v.size())
        return core::make_error(
            "between-value spread: need two or more values with one uncertainty each, got " +
            std::to_string(v.size()) + " and " + std::to_string(u.size()));
    constexpr double kMinU = 1e-6;
    double s1 = 0, s2 = 0, swv = 0;
    std::vector<double> w(v.size());
    for (std::size_t i = 0; i < v.size(); ++i) {
        if (!std::isfinite(v[i]) || !std::isfinite(u[i]) || u[i] < 0)
            return core::make_error("between-value spread: value " + std::to_string(i) +
                                    " is not finite or has a negative uncertainty");
        const double ui = std::max(u[i], kMinU);
        w[i] = 1.0 / (ui * ui);
        s1 += w[i];
        s2 += w[i] * w[i];
        swv += w[i] * v[i];
    }
    const double mean = swv / s1;
    double q = 0;  // Cochran's Q: weighted squares about the weighted mean
    for (std::size_t i = 0; i < v.size(); ++i) q += w[i] * (v[i] - mean) * (v[i] - mean);
    const double tau2 = (q - static_cast<double>(v.size() - 1)) / (s1 - s2 / s1);
    return std::sqrt(std::max(0.0, tau2));
}

}  // namespace hotgauge::measure
