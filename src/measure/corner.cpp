// The corner profile of a forged edge (docs/measurement.md, "Real forgings"): plane, fillet arc
// and drafted wall in the half-plane about the circle's own centre, fitted by Levenberg–Marquardt
// with analytic derivatives and 3σ rejection.
#include "corner.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

namespace hotgauge::measure::detail {
namespace {

using Vec7 = Eigen::Matrix<double, 7, 1>;  // centre x, centre y, radius, t, rho, rho2, depth
using Mat7 = Eigen::Matrix<double, 7, 7>;

CornerModel from(const Vec7& x) { return {{x[0], x[1]}, x[2], x[3], x[4], x[6], x[5]}; }
Vec7 to(const CornerModel& m) {
    Vec7 x;
    x << m.centre.x(), m.centre.y(), m.radius, m.t, m.rho, m.rho2, m.depth;
    return x;
}

// The distance from (s, h) to the profile along its normal: its value, the normal n (its gradient
// in (s, h)), its derivatives in t, rho, rho2 and depth at fixed (s, h), and the part of the
// profile nearest.
struct Ortho {
    double e = 0;
    Eigen::Vector2d n = Eigen::Vector2d::UnitY();
    double de_dt = 0, de_drho = 0, de_drho2 = 0, de_ddepth = 0;
    int where = 0;  // 0 plane, 1 fillet, 2 wall, 3 far fillet, 4 far level
};
// The far fillet's centre: rho2 from the wall and from the far level h = −depth, outside the
// material (k = √(1 + t²)).
Eigen::Vector2d far_centre(const CornerModel& m, double k) {
    return {m.rho2 * k + m.t * (m.depth - m.rho2), m.rho2 - m.depth};
}
// What the profile's distance needs of the model, computed once per pass over the samples, not
// once per sample (the corner fits are half of a forged part's measurement).
struct Shape {
    CornerModel m;
    double k;               // √(1 + t²)
    Eigen::Vector2d c;      // the fillet's centre: rho from the plane and the wall, in the material
    Eigen::Vector2d n2;     // the wall's normal, out of the material
    Eigen::Vector2d down;   // along the wall, away from the plane
    Eigen::Vector2d c_end;  // where the fillet meets the wall
    Eigen::Vector2d c2;     // the far fillet's centre
    Eigen::Vector2d c2_end;  // where the far fillet meets the wall
    explicit Shape(const CornerModel& model)
        : m(model),
          k(std::sqrt(1.0 + m.t * m.t)),
          c(-m.rho * k + m.t * m.rho, -m.rho),
          n2(1.0 / k, m.t / k),
          down(m.t / k, -1.0 / k),
          c_end(c + m.rho * n2),
          c2(far_centre(m, k)),
          c2_end(c2 - m.rho2 * n2) {}
};
// Beyond the wall's lower end (a far corner): the concave fillet about c2, then the far level.
void far_corner(const Shape& g, const Eigen::Vector2d& ps, Ortho& o) {
    const CornerModel& m = g.m;
    if (ps.x() >= g.c2.x()) {
        o.where = 4;
        o.e = ps.y() + m.depth;
        o.de_ddepth = 1.0;
        return;
    }
    o.where = 3;
    const Eigen::Vector2d dv = ps - g.c2;
    const double L = std::max(dv.norm(), 1e-12);
    o.e = m.rho2 - L;  // nearer c2 than rho2: out of the material
    o.n = -dv / L;
    // e moves with c2 as −n·dc2: dc2/dt, dc2/drho2, dc2/ddepth.
    o.de_dt = -o.n.x() * (m.rho2 * m.t / g.k + m.depth - m.rho2);
    o.de_drho2 = 1.0 - o.n.x() * (g.k - m.t) - o.n.y();
    o.de_ddepth = -o.n.x() * m.t + o.n.y();
}
Ortho ortho(const Shape& g, double s, double h) {
    const CornerModel& m = g.m;
    const double k = g.k;
    const Eigen::Vector2d ps(s, h);
    Ortho o;
    if (s <= g.c.x()) {
        o.e = h;
    } else if ((ps - g.c_end).dot(g.down) >= 0.0) {
        if (m.depth > 0.0 && (ps - g.c2_end).dot(g.down) >= 0.0) {  // past the wall
            far_corner(g, ps, o);
            return o;
        }
        o.where = 2;
        o.e = (s + m.t * h) / k;
        o.n = g.n2;
        o.de_dt = h / k - (s + m.t * h) * m.t / (k * k * k);
    } else {
        o.where = 1;
        const Eigen::Vector2d dv = ps - g.c;
        const double D = std::max(dv.norm(), 1e-12);
        o.e = D - m.rho;
        o.n = dv / D;
        o.de_dt = -o.n.x() * m.rho * (1.0 - m.t / k);
        o.de_drho = -o.n.x() * (m.t - k) + o.n.y() - 1.0;
    }
    return o;
}

// Residual and its gradient with respect to (cx, cy, radius, t, rho, rho2, depth). With the
// sample's ray, the residual is the distance along the ray to the profile: the range noise lies
// along the ray, and an orthogonal fit of a fillet seen along the axis, whose steep part turns that
// noise sideways, read the corner 5-8 µm small at σ 0.05 mm (a 2-D model: −7.7 µm orthogonal, −0.2
// µm along the ray; the same samples with the noise along the normal +1.1 µm). Where the ray
// grazes the profile (within 12° of it) or does not meet it, the orthogonal distance over the
// cosine at its foot, the cosine held at that of 12°: the along-ray distance to first order, and
// what the along-ray distance tends to at 12°. Falling back to the bare orthogonal distance
// instead made the cost jump by up to 5× where a sample changed sides, and the fit stopped
// wherever the jumps left it: up to 13 µm apart between two convergence tolerances (a forged
// part's Diameter 5); now 0.001 µm.
constexpr double kGrazing = 0.2;
// Newton steps along the ray to the profile at most; converged within kRayTolMm, and the ray
// meets the profile when it ends within kRayMeetMm of it (not measured).
constexpr int kRayNewtonSteps = 6;
constexpr double kRayTolMm = 1e-9, kRayMeetMm = 1e-6;
double residual(const Shape& shape, double side, const CornerPoint& p, Vec7* grad, int* part) {
    const CornerModel& m = shape.m;
    const Eigen::Vector2d d = p.q - m.centre;
    const double r = std::max(d.norm(), 1e-9);
    const double s = side * (r - m.radius), h = p.h;
    // ds/d(cx, cy, radius); s does not depend on t or rho.
    const Eigen::Vector2d ds_dc = -side * d / r;
    const double ds_dr0 = -side;
    Ortho o = ortho(shape, s, h);
    double e = o.e, scale = 1.0;
    if (p.ray.squaredNorm() > 0.0) {
        const Eigen::Vector2d ray(side * p.ray.x(), p.ray.y());  // (s, h), towards the sensor
        double lambda = 0;
        Ortho at = o;
        bool ok = true;
        for (int it = 0; it < kRayNewtonSteps && ok; ++it) {
            const double nd = at.n.dot(ray);
            ok = std::abs(nd) >= kGrazing;
            if (!ok) break;
            lambda -= at.e / nd;
            at = ortho(shape, s + lambda * ray.x(), h + lambda * ray.y());
            if (std::abs(at.e) < kRayTolMm) break;
        }
        if (ok && std::abs(at.n.dot(ray)) >= kGrazing && std::abs(at.e) < kRayMeetMm) {
            o = at;
            e = -lambda;
            scale = 1.0 / at.n.dot(ray);
        } else {
            scale = 1.0 / std::max(o.n.dot(ray), kGrazing);
            e = scale * o.e;
        }
    }
    if (part) *part = o.where;
    if (grad) {
        Vec7& g = *grad;
        g.head<2>() = scale * o.n.x() * ds_dc;
        g[2] = scale * o.n.x() * ds_dr0;
        g[3] = scale * o.de_dt;
        g[4] = scale * o.de_drho;
        g[5] = scale * o.de_drho2;
        g[6] = scale * o.de_ddepth;
    }
    return e;
}

// One Levenberg–Marquardt solve on the inliers, with the priors as more residuals.
struct Solve {
    Vec7 x;
    Mat7 JtJ;
    double rms = 0;
};
// A prior on parameter j: mean ± sigma, its weight multiplied by `hold` in the fit (a held
// parameter) and by `hold_u` in the covariance.
struct Prior1 {
    int j;
    double mean, sigma, hold, hold_u;
};
// The fit's thinning (kFitSamples below) in two strata: the samples beyond the plane by more than
// kBeyondPlaneMm (the fillet's and the wall's: what fixes the corner, a few hundred on a short
// wall) and the rest (the plane's, the bulk). Each kept sample stands for 1 / its stratum's
// fraction.
struct Thinning {
    std::array<double, 2> keep{1.0, 1.0};  // the fraction kept: near the plane, beyond it
    double of(const CornerPoint& p) const { return keep[p.beyond_plane() ? 1 : 0]; }
    double weight(const CornerPoint& p) const { return 1.0 / of(p); }
};

// The normal equations of the thinned samples `use` at v (no priors): JᵀJ, Jᵀe and the sum of
// squares, each fitted sample standing for 1 / its stratum's fraction of them; n, the samples
// they stand for.
struct Normal {
    Mat7 A = Mat7::Zero();
    Vec7 b = Vec7::Zero();
    double sse = 0;
    double n = 0;
};
Normal normal_equations(const std::vector<CornerPoint>& pts, const std::vector<std::uint32_t>& used,
                        double side, const Vec7& v, const Thinning& th) {
    Normal out;
    const Shape shape(from(v));
    for (const std::uint32_t q : used) {
        Vec7 g;
        int part = 0;
        const double e = residual(shape, side, pts[q], &g, &part), w = th.weight(pts[q]);
        out.sse += w * e * e;
        out.n += w;
        if (part == 0) continue;  // on the plane, h: no parameter moves it (g = 0)
        out.A.noalias() += (w * g) * g.transpose();  // fixed-size: far faster than rankUpdate
        out.b += (w * e) * g;
    }
    return out;
}

// The draft: weak (the middle of the drawing's range), or held (a wall out of view, its u the
// prior's). A far corner's fillet and depth: weak (the drawing's range, the step's nominal depth
// ± 0.5 mm); without a far corner both are held at 0.
using Priors = std::array<Prior1, 3>;
Priors corner_priors(const CornerPrior& prior) {
    constexpr double kHeld = 1e10, kDepthSigmaMm = 0.5;
    // The far fillet's range never below 0.1 mm: its sigma divides the prior's weight.
    constexpr double kMinRhoRangeMm = 0.1;
    const bool far = prior.depth > 0.0;
    const double far_hold = far ? 1.0 : kHeld;
    return {{
        {3, prior.t_mean(), prior.t_sigma(), prior.fix_draft ? kHeld : 1.0, 1.0},
        {5, far ? 0.5 * prior.rho_max : 0.0,
         std::max(prior.rho_max, kMinRhoRangeMm) / std::sqrt(12.0), far_hold, far_hold},
        {6, prior.depth, kDepthSigmaMm, far_hold, far_hold},
    }};
}

// The priors as more residuals, each weighted by the samples' variance sigma2: the normal
// equations A, b and the cost at v with them, from m (the samples' at v).
double with_priors(const Priors& priors, double sigma2, const Vec7& v, const Normal& m, Mat7& A,
                   Vec7& b) {
    A = m.A;
    b = m.b;
    double c = m.sse;
    for (const Prior1& p : priors) {
        const double w = p.hold * sigma2 / (p.sigma * p.sigma), d = v[p.j] - p.mean;
        A(p.j, p.j) += w;
        b[p.j] += w * d;
        c += w * d * d;
    }
    return c;
}

// The samples in use, listed once: a solve passes over them 5-30 times.
std::vector<std::uint32_t> listed(const std::vector<char>& use) {
    std::vector<std::uint32_t> used;
    used.reserve(use.size());
    for (std::size_t q = 0; q < use.size(); ++q)
        if (use[q]) used.push_back(static_cast<std::uint32_t>(q));
    return used;
}

// x + step inside the model's range: a draft only opens the corner (t ≥ 0), the fillets between
// 0 and twice the drawing's largest + 0.5 mm, a far corner at least 0.05 mm deep.
Vec7 step_within(const Vec7& x, const Vec7& step, const CornerPrior& prior) {
    constexpr double kRhoSlackMm = 0.5, kMinDepthMm = 0.05;
    Vec7 xn = x + step;
    xn[3] = std::max(0.0, xn[3]);
    xn[4] = std::clamp(xn[4], 0.0, 2.0 * prior.rho_max + kRhoSlackMm);
    xn[5] = std::clamp(xn[5], 0.0, 2.0 * prior.rho_max + kRhoSlackMm);
    if (prior.depth > 0.0) xn[6] = std::max(xn[6], kMinDepthMm);
    return xn;
}

// The normal matrix at the solution with the priors in it: where the samples do not fix the
// draft (a wall out of view), its covariance is the prior's, and u says what that costs.
Mat7 normal_for_u(const Normal& raw, const Priors& priors, double rms2, double min_sigma2) {
    Mat7 A = raw.A;
    for (const Prior1& p : priors)
        A(p.j, p.j) += p.hold_u * std::max(rms2, min_sigma2) / (p.sigma * p.sigma);
    return A;
}

// Levenberg–Marquardt steps of a solve at most (not measured).
constexpr int kMaxSolveSteps = 30;
// The jackknife's groups start from the whole fit's solution: this many steps reach theirs.
constexpr int kJackknifeSteps = 3;

Solve solve(const std::vector<CornerPoint>& pts, const std::vector<char>& use, double side, Vec7 x,
            const CornerPrior& prior, const Thinning& th, int iterations = kMaxSolveSteps) {
    // Levenberg–Marquardt's damping: its start, its factors on an accepted and a rejected step,
    // its floor, and the ceiling beyond which no step lowers the cost; the damping's floor on a
    // diagonal the samples leave empty.
    constexpr double kLambdaStart = 1e-3, kLambdaDown = 0.3, kLambdaUp = 10.0;
    constexpr double kLambdaMin = 1e-9, kLambdaMax = 1e8, kDampFloor = 1e-9;
    // A nanometre, or a cost that no longer moves: converged (the results then agree to 0.001 µm
    // with a 100× tighter tolerance).
    constexpr double kStepTolMm = 1e-6, kCostTolRel = 1e-9;
    constexpr double kMinSigma2 = 1e-6;  // mm²: the priors' weight against a (near) exact fit
    const Priors priors = corner_priors(prior);
    const std::vector<std::uint32_t> used = listed(use);
    Normal raw = normal_equations(pts, used, side, x, th);  // at x, without the priors
    const double n = std::max(raw.n, 1.0);
    const double sigma2 = std::max(raw.sse / n, kMinSigma2);
    Mat7 A;
    Vec7 b;
    double c0 = with_priors(priors, sigma2, x, raw, A, b), lambda = kLambdaStart;
    for (int it = 0; it < iterations; ++it) {
        Mat7 M = A;
        M.diagonal() += lambda * (A.diagonal().array() + kDampFloor).matrix();
        const Vec7 step = -M.ldlt().solve(b);
        const Vec7 xn = step_within(x, step, prior);
        const Normal next = normal_equations(pts, used, side, xn, th);
        Mat7 An;
        Vec7 bn;
        const double c1 = with_priors(priors, sigma2, xn, next, An, bn);
        if (c1 < c0) {
            const bool done = c0 - c1 < kCostTolRel * c0 || step.norm() < kStepTolMm;
            x = xn, A = An, b = bn, c0 = c1, raw = next;
            lambda = std::max(lambda * kLambdaDown, kLambdaMin);
            if (done) break;
        } else {
            // A step that raises the cost by no more than the tolerance: x is the minimum to
            // within it, as when a step lowers it by no more (more steps only raise lambda).
            if (c1 - c0 < kCostTolRel * c0) break;
            lambda *= kLambdaUp;
            if (lambda > kLambdaMax) break;
        }
    }
    const double rms2 = raw.sse / n;
    return {x, normal_for_u(raw, priors, rms2, kMinSigma2), std::sqrt(rms2)};
}

// The samples of one profile share its vibration residual and pose error, which the formal u
// counts as independent noise (a fillet seen in 270 profiles by 10 000 samples). The jackknife
// over kGroups interleaved groups of profiles (each group sees the whole circle, the groups'
// errors are independent) measures what they cost: the radius fitted without each group in turn.
double jackknife_u(const std::vector<CornerPoint>& pts, const std::vector<char>& use, double side,
                   const Vec7& x, const CornerPrior& prior, const Thinning& th) {
    constexpr int kGroups = 4;
    if (pts.empty() || pts.front().profile < 0) return 0.0;
    std::array<double, kGroups> radius{};
    for (int g = 0; g < kGroups; ++g) {
        std::vector<char> keep = use;
        for (std::size_t q = 0; q < pts.size(); ++q)
            keep[q] = keep[q] && pts[q].profile % kGroups != g;
        // From the whole fit's solution a few steps reach the group's: they differ by its share.
        radius[g] = solve(pts, keep, side, x, prior, th, kJackknifeSteps).x[2];
    }
    double mean = 0, var = 0;
    for (const double r : radius) mean += r / kGroups;
    for (const double r : radius) var += (r - mean) * (r - mean);
    return std::sqrt(var * (kGroups - 1) / kGroups);
}

// Floors on the draft prior's σ (tan): a side draft's u, and the drawing's draft range
// (not measured).
constexpr double kMinDraftU = 1e-4, kMinDraftRange = 1e-3;

}  // namespace

double CornerPrior::t_sigma() const {
    return t_known_u ? std::max(*t_known_u, kMinDraftU)
                     : std::max(t_max, kMinDraftRange) / std::sqrt(12.0);
}

double corner_residual(const CornerModel& m, double side, const CornerPoint& p, int* part) {
    return residual(Shape(m), side, p, nullptr, part);
}

namespace {

// The fit runs on a thinning to about kFitSamples (a corner's seven parameters need far fewer
// than the 10 000-50 000 samples near it; each fitted one stands for 1 / its stratum's fraction,
// so u is that of all); inliers and counts are taken on all of them. Beyond the plane at most half
// of them, the plane the rest. A sample is kept by a hash of its key, so that which are kept does
// not depend on which samples the window took in: every stride-th of the window's list had moved a
// recess corner 5 µm on the radius when a pose 1 µm apart let a few samples more in at the window's
// edge (independent-forged-401's Diameter 5 read +0.014, +0.017 or +0.028 mm by pose).
constexpr std::size_t kFitSamples = 6000;
Thinning thinning(const std::vector<CornerPoint>& pts) {
    const auto beyond = static_cast<double>(std::count_if(
        pts.begin(), pts.end(), [](const CornerPoint& p) { return p.beyond_plane(); }));
    const double near = static_cast<double>(pts.size()) - beyond, half = kFitSamples / 2.0;
    Thinning th;
    th.keep[1] = beyond > half ? half / beyond : 1.0;
    const double left = kFitSamples - beyond * th.keep[1];
    th.keep[0] = near > left ? left / near : 1.0;
    return th;
}
// A sample is kept when the hash of its key, as a fraction in [0, 1), is below its stratum's
// fraction: a window a few samples larger keeps the same ones and a few more (the kept sets
// are nested), not another draw.
bool thinned_in(const std::vector<CornerPoint>& pts, std::size_t q, const Thinning& th) {
    const double keep = th.of(pts[q]);
    if (keep >= 1.0) return true;
    std::uint64_t h = static_cast<std::uint64_t>(pts[q].sample >= 0 ? pts[q].sample
                                                                    : static_cast<std::int64_t>(q));
    h *= 0x9E3779B97F4A7C15ull;
    h ^= h >> 29;
    h *= 0xBF58476D1CE4E5B9ull;
    h ^= h >> 32;
    return static_cast<double>(h >> 11) * 0x1.0p-53 < keep;
}
// Inliers: within 3σ of the profile, never tighter than 0.02 mm (not measured).
constexpr double kInlierK = 3.0, kMinInlierMm = 0.02;
double inlier_threshold(double rms) { return std::max(kInlierK * rms, kMinInlierMm); }

// `rounds` times: the solve on the thinned samples `use`, then as `use` the thinned samples within
// the inlier threshold of its solution.
Solve robust_solve(const std::vector<CornerPoint>& pts, std::vector<char>& use, double side, Vec7 x,
                   const CornerPrior& prior, const Thinning& th, int rounds) {
    Solve s;
    for (int round = 0; round < rounds; ++round) {
        s = solve(pts, use, side, x, prior, th);
        x = s.x;
        const double thr = inlier_threshold(s.rms);
        const Shape shape(from(x));
        for (std::size_t q = 0; q < pts.size(); ++q)
            use[q] = thinned_in(pts, q, th) &&
                     std::abs(residual(shape, side, pts[q], nullptr, nullptr)) <= thr;
    }
    return s;
}

// The radius's standard uncertainty from the normal matrix; infinite where the samples do not fix
// it (its smallest eigenvalue 1e-14 of its largest, or less).
constexpr double kUnfixedRel = 1e-14;
double radius_u(const Solve& s) {
    const Eigen::SelfAdjointEigenSolver<Mat7> eig(s.JtJ);
    const auto& ev = eig.eigenvalues();  // ascending
    if (eig.info() != Eigen::Success || !(ev[0] > kUnfixedRel * ev[6]))
        return std::numeric_limits<double>::infinity();
    const Mat7 cov = eig.eigenvectors() * ev.cwiseInverse().asDiagonal() *
                     eig.eigenvectors().transpose() * s.rms * s.rms;
    return std::sqrt(std::max(0.0, cov(2, 2)));
}

// The sectors' radii: 8 sectors (docs/measurement.md, "Real forgings"), each from at least 10
// inliers or 1/32 of the fillet's and wall's (not measured).
constexpr int kSectors = 8, kMinInSector = 10, kSectorShareDivisor = 32;
// Rounds of solve and inlier selection of a corner's fit (not measured); a refit at a side draft
// twice (refit_draft).
constexpr int kRobustRounds = 3, kRefitRounds = 2;

// The fit `s` on the thinned inliers `use` as a CornerFit: inliers of every sample by the part of
// the profile, sectors, u (formal, or the jackknife's when `jackknife` and larger) and, for a fit
// whose u is `reported`, each profile's radial weight.
CornerFit summarize(const std::vector<CornerPoint>& pts, double side, const Solve& s,
                    const std::vector<char>& use, const CornerPrior& prior, const Thinning& th,
                    bool reported, bool jackknife) {
    const double thr = inlier_threshold(s.rms);
    CornerFit out;
    out.m = from(s.x);
    out.rms = s.rms;
    std::vector<double> sum(kSectors, 0.0);
    std::vector<int> cnt(kSectors, 0);
    const Shape shape(out.m);
    for (std::size_t q = 0; q < pts.size(); ++q) {  // every sample: inlier, part, sector
        int part = 0;
        const double e = residual(shape, side, pts[q], nullptr, &part);
        if (std::abs(e) > thr) continue;
        (part == 0 ? out.n_plane : part == 1 ? out.n_arc : part == 2 ? out.n_wall : out.n_far)++;
        if (part == 0 || part >= 3) continue;  // the corner's circle: its fillet and wall
        const Eigen::Vector2d d = pts[q].q - out.m.centre;
        if (reported) {
            if (out.radial.empty() || out.radial.back().first != pts[q].profile)
                out.radial.emplace_back(pts[q].profile, Eigen::Vector2d::Zero());
            out.radial.back().second += d.normalized();
        }
        const double turn = (std::atan2(d.y(), d.x()) + std::numbers::pi) / (2 * std::numbers::pi);
        const int sec = std::min(kSectors - 1, static_cast<int>(turn * kSectors));
        sum[sec] += side * e;  // samples beyond the profile: a larger circle (outer edge)
        cnt[sec]++;
    }
    std::sort(out.radial.begin(), out.radial.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    std::size_t kept = 0;
    for (std::size_t q = 0; q < out.radial.size(); ++q) {
        if (kept > 0 && out.radial[kept - 1].first == out.radial[q].first)
            out.radial[kept - 1].second += out.radial[q].second;
        else
            out.radial[kept++] = out.radial[q];
    }
    out.radial.resize(kept);
    const std::int64_t n_profile = out.n_arc + out.n_wall;
    for (int sec = 0; sec < kSectors; ++sec)
        if (cnt[sec] >= std::max<std::int64_t>(kMinInSector, n_profile / kSectorShareDivisor))
            out.sector_radius.push_back(out.m.radius + sum[sec] / cnt[sec]);
    out.u_radius = radius_u(s);
    if (std::isfinite(out.u_radius)) {
        if (jackknife) {
            out.u_jackknife = jackknife_u(pts, use, side, s.x, prior, th);
            out.u_radius = std::max(out.u_radius, out.u_jackknife);
        }
    }
    return out;
}

}  // namespace

CornerFit fit_corner(const std::vector<CornerPoint>& pts, double side, const CornerModel& start,
                     const CornerPrior& prior, bool jackknife) {
    const Thinning th = thinning(pts);
    std::vector<char> use(pts.size(), 0);
    for (std::size_t q = 0; q < pts.size(); ++q) use[q] = thinned_in(pts, q, th);
    Vec7 x = to(start);
    if (prior.depth <= 0.0) {
        x[5] = x[6] = 0.0;  // no far corner
    } else {
        if (x[5] <= 0.0) x[5] = 0.5 * prior.rho_max;
        if (x[6] <= 0.0) x[6] = prior.depth;
    }
    const Solve s = robust_solve(pts, use, side, x, prior, th, kRobustRounds);
    return summarize(pts, side, s, use, prior, th, jackknife, jackknife);
}

CornerFit refit_draft(const std::vector<CornerPoint>& pts, double side, const CornerFit& held,
                      const CornerPrior& prior) {
    const Thinning th = thinning(pts);
    const double thr = inlier_threshold(held.rms);
    std::vector<char> use(pts.size(), 0);
    const Shape shape(held.m);
    for (std::size_t q = 0; q < pts.size(); ++q)
        use[q] = thinned_in(pts, q, th) &&
                 std::abs(residual(shape, side, pts[q], nullptr, nullptr)) <= thr;
    Vec7 x = to(held.m);
    x[3] = prior.t_mean();
    // Twice: the held fit's inliers are those of the drawing's draft, which may take in wall
    // samples the side draft puts outside (and the solve on them stops 20-40 µm off).
    const Solve s = robust_solve(pts, use, side, x, prior, th, kRefitRounds);
    CornerFit out = summarize(pts, side, s, use, prior, th, true, false);
    // The jackknife measures the profiles' shared errors, which a change of draft leaves alone.
    out.u_jackknife = held.u_jackknife;
    out.u_radius = std::max(out.u_radius, held.u_jackknife);
    return out;
}

}  // namespace hotgauge::measure::detail
