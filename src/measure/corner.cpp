// The corner profile of a forged edge (docs/measurement.md, "Real forgings"): plane, fillet arc
// and drafted wall in the half-plane about the circle's own centre, fitted by Levenberg–Marquardt
// with analytic derivatives and 3σ rejection.
#include "corner.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace hotgauge::measure::detail {
namespace {

using Vec5 = Eigen::Matrix<double, 5, 1>;  // centre x, centre y, radius, t, rho
using Mat5 = Eigen::Matrix<double, 5, 5>;

CornerModel from(const Vec5& x) { return {{x[0], x[1]}, x[2], x[3], x[4]}; }
Vec5 to(const CornerModel& m) {
    Vec5 x;
    x << m.centre.x(), m.centre.y(), m.radius, m.t, m.rho;
    return x;
}

// The distance from (s, h) to the profile along its normal: its value, the normal n (its gradient
// in (s, h)), its derivatives in t and rho at fixed (s, h), and the part of the profile nearest.
struct Ortho {
    double e = 0;
    Eigen::Vector2d n = Eigen::Vector2d::UnitY();
    double de_dt = 0, de_drho = 0;
    int where = 0;  // 0 plane, 1 fillet, 2 wall
};
Ortho ortho(const CornerModel& m, double s, double h) {
    const double k = std::sqrt(1.0 + m.t * m.t);
    // Fillet centre (s_c, h_c): rho from the plane and from the wall, inside the material.
    const Eigen::Vector2d c(-m.rho * k + m.t * m.rho, -m.rho);
    const Eigen::Vector2d n2(1.0 / k, m.t / k);     // wall normal, out of the material
    const Eigen::Vector2d down(m.t / k, -1.0 / k);  // along the wall, away from the plane
    const Eigen::Vector2d ps(s, h);
    Ortho o;
    if (s <= c.x()) {
        o.e = h;
    } else if ((ps - (c + m.rho * n2)).dot(down) >= 0.0) {
        o.where = 2;
        o.e = (s + m.t * h) / k;
        o.n = n2;
        o.de_dt = h / k - (s + m.t * h) * m.t / (k * k * k);
    } else {
        o.where = 1;
        const Eigen::Vector2d dv = ps - c;
        const double D = std::max(dv.norm(), 1e-12);
        o.e = D - m.rho;
        o.n = dv / D;
        o.de_dt = -o.n.x() * m.rho * (1.0 - m.t / k);
        o.de_drho = -o.n.x() * (m.t - k) + o.n.y() - 1.0;
    }
    return o;
}

// Residual and its gradient with respect to (cx, cy, radius, t, rho). With the sample's ray, the
// residual is the distance along the ray to the profile: the range noise lies along the ray, and
// an orthogonal fit of a fillet seen along the axis, whose steep part turns that noise
// sideways, read the corner 5-8 µm small at σ 0.05 mm (a 2-D model: −7.7 µm orthogonal, −0.2 µm
// along the ray; the same samples with the noise along the normal +1.1 µm). Grazing rays (the
// ray within 12° of the profile) keep the orthogonal distance.
double residual(const CornerModel& m, double side, const CornerPoint& p, Vec5* grad, int* part) {
    const Eigen::Vector2d d = p.q - m.centre;
    const double r = std::max(d.norm(), 1e-9);
    const double s = side * (r - m.radius), h = p.h;
    // ds/d(cx, cy, radius); s does not depend on t or rho.
    const Eigen::Vector2d ds_dc = -side * d / r;
    const double ds_dr0 = -side;
    Ortho o = ortho(m, s, h);
    double e = o.e, scale = 1.0;
    if (p.ray.squaredNorm() > 0.0) {
        const Eigen::Vector2d ray(side * p.ray.x(), p.ray.y());  // (s, h), towards the sensor
        double lambda = 0;
        Ortho at = o;
        bool ok = true;
        for (int it = 0; it < 6 && ok; ++it) {
            const double nd = at.n.dot(ray);
            ok = std::abs(nd) >= 0.2;
            if (!ok) break;
            lambda -= at.e / nd;
            at = ortho(m, s + lambda * ray.x(), h + lambda * ray.y());
            if (std::abs(at.e) < 1e-9) break;
        }
        if (ok && std::abs(at.n.dot(ray)) >= 0.2 && std::abs(at.e) < 1e-6) {
            o = at;
            e = -lambda;
            scale = 1.0 / at.n.dot(ray);
        }
    }
    if (part) *part = o.where;
    if (grad) {
        Vec5& g = *grad;
        g.head<2>() = scale * o.n.x() * ds_dc;
        g[2] = scale * o.n.x() * ds_dr0;
        g[3] = scale * o.de_dt;
        g[4] = scale * o.de_drho;
    }
    return e;
}

// One Levenberg–Marquardt solve on the inliers, with the draft's prior as one more residual.
struct Solve {
    Vec5 x;
    Mat5 JtJ;
    double rms = 0;
};
Solve solve(const std::vector<CornerPoint>& pts, const std::vector<char>& use, double side, Vec5 x,
            const CornerPrior& prior, double weight) {
    const double t_mean = prior.t_mean(), t_sigma = prior.t_sigma();
    const double hold = prior.fix_draft ? 1e10 : 1.0;  // a held draft: the prior alone
    double lambda = 1e-3;
    auto cost = [&](const Vec5& v, Mat5* JtJ, Vec5* Jte, double* sse, std::size_t* n) {
        Mat5 A = Mat5::Zero();
        Vec5 b = Vec5::Zero();
        double s2 = 0;
        std::size_t cnt = 0;
        for (std::size_t q = 0; q < pts.size(); ++q) {
            if (!use[q]) continue;
            Vec5 g;
            const double e = residual(from(v), side, pts[q], &g, nullptr);
            A.selfadjointView<Eigen::Lower>().rankUpdate(g);
            b += g * e;
            s2 += e * e;
            ++cnt;
        }
        // Every weight-th sample is fitted (a thinned set), each standing for `weight` of them.
        A = weight * Mat5(A.selfadjointView<Eigen::Lower>());
        b *= weight;
        s2 *= weight;
        if (sse) *sse = s2;
        if (n) *n = static_cast<std::size_t>(static_cast<double>(cnt) * weight);
        if (JtJ) *JtJ = A;
        if (Jte) *Jte = b;
        return s2;
    };
    Mat5 A;
    Vec5 b;
    double sse = 0;
    std::size_t n = 0;
    cost(x, &A, &b, &sse, &n);
    const double sigma2 = std::max(sse / static_cast<double>(std::max<std::size_t>(n, 1)), 1e-6);
    auto with_prior = [&](const Vec5& v, Mat5& M, Vec5& g, double& c) {
        const double w = hold * sigma2 / (t_sigma * t_sigma);
        M(3, 3) += w;
        g[3] += w * (v[3] - t_mean);
        c += w * (v[3] - t_mean) * (v[3] - t_mean);
    };
    double c0 = sse;
    with_prior(x, A, b, c0);
    for (int it = 0; it < 30; ++it) {
        Mat5 M = A;
        M.diagonal() += lambda * (A.diagonal().array() + 1e-9).matrix();
        const Vec5 step = -M.ldlt().solve(b);
        Vec5 xn = x + step;
        xn[3] = std::max(0.0, xn[3]);
        xn[4] = std::clamp(xn[4], 0.0, 2.0 * prior.rho_max + 0.5);
        Mat5 An;
        Vec5 bn;
        double c1 = 0;
        cost(xn, &An, &bn, &c1, &n);
        with_prior(xn, An, bn, c1);
        if (c1 < c0) {
            const bool done = c0 - c1 < 1e-10 * c0 || step.norm() < 1e-7;
            x = xn, A = An, b = bn, c0 = c1;
            lambda = std::max(lambda * 0.3, 1e-9);
            if (done) break;
        } else {
            lambda *= 10.0;
            if (lambda > 1e8) break;
        }
    }
    // The normal matrix at the solution with the prior in it: where the samples do not fix the
    // draft (a wall out of view), its covariance is the prior's, and u says what that costs.
    cost(x, &A, nullptr, &sse, &n);
    const double rms2 = sse / static_cast<double>(std::max<std::size_t>(n, 1));
    A(3, 3) += std::max(rms2, 1e-6) / (t_sigma * t_sigma);  // held or not: the draft's u
    return {x, A, std::sqrt(rms2)};
}

}  // namespace

double CornerPrior::t_sigma() const {
    return t_known_u ? std::max(*t_known_u, 1e-4) : std::max(t_max, 1e-3) / std::sqrt(12.0);
}

double corner_residual(const CornerModel& m, double side, const CornerPoint& p, int* part) {
    return residual(m, side, p, nullptr, part);
}

CornerFit fit_corner(const std::vector<CornerPoint>& pts, double side, const CornerModel& start,
                     const CornerPrior& prior) {
    // The fit runs on an even thinning to kFitSamples (a corner's five parameters need far fewer
    // than the 10 000-50 000 samples near it; each fitted one stands for `stride`, so u is that
    // of all); inliers and counts are taken on all of them.
    constexpr std::size_t kFitSamples = 6000;
    const std::size_t stride = std::max<std::size_t>(1, pts.size() / kFitSamples);
    std::vector<char> use(pts.size(), 0);
    for (std::size_t q = 0; q < pts.size(); q += stride) use[q] = 1;
    Vec5 x = to(start);
    Solve s;
    for (int round = 0; round < 3; ++round) {
        s = solve(pts, use, side, x, prior, static_cast<double>(stride));
        x = s.x;
        const double thr = std::max(3.0 * s.rms, 0.02);
        for (std::size_t q = 0; q < pts.size(); ++q)
            use[q] = q % stride == 0 &&
                     std::abs(residual(from(x), side, pts[q], nullptr, nullptr)) <= thr;
    }
    const double thr = std::max(3.0 * s.rms, 0.02);
    CornerFit out;
    out.m = from(x);
    out.rms = s.rms;
    std::vector<double> sum(8, 0.0);
    std::vector<int> cnt(8, 0);
    for (std::size_t q = 0; q < pts.size(); ++q) {  // every sample: inlier, part, sector
        int part = 0;
        const double e = residual(out.m, side, pts[q], nullptr, &part);
        if (std::abs(e) > thr) continue;
        (part == 0 ? out.n_plane : part == 1 ? out.n_arc : out.n_wall)++;
        if (part == 0) continue;
        const Eigen::Vector2d d = pts[q].q - out.m.centre;
        const double turn = (std::atan2(d.y(), d.x()) + std::numbers::pi) / (2 * std::numbers::pi);
        const int sec = std::min(7, static_cast<int>(turn * 8));
        sum[sec] += side * e;  // samples beyond the profile: a larger circle (outer edge)
        cnt[sec]++;
    }
    const std::int64_t n_profile = out.n_arc + out.n_wall;
    for (int sec = 0; sec < 8; ++sec)
        if (cnt[sec] >= std::max<std::int64_t>(10, n_profile / 32))
            out.sector_radius.push_back(out.m.radius + sum[sec] / cnt[sec]);
    const Eigen::LDLT<Mat5> ldlt(s.JtJ);
    out.u_radius = std::numeric_limits<double>::infinity();  // the samples do not fix it
    if (ldlt.info() == Eigen::Success && ldlt.rcond() > 1e-14) {
        const Mat5 cov = ldlt.solve(Mat5::Identity()) * s.rms * s.rms;
        out.u_radius = std::sqrt(std::max(0.0, cov(2, 2)));
    }
    return out;
}

}  // namespace hotgauge::measure::detail
