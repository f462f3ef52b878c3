// Ray crossings, grid normals and the bracket estimators (docs/measurement.md).
#include "edges.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

namespace hotgauge::measure::detail {
namespace {

// The grid neighbourhood of a sample's normal: 5×5 samples (docs/measurement.md, "Edges and
// circles"), of which at least this many valid for a PCA normal (not measured).
constexpr std::int64_t kGridHalf = 2;
constexpr int kMinNormalSamples = 6;
// Rounds of robust_mean's rejection at most (not measured).
constexpr int kMeanRounds = 10;
// Brackets that may miss the stabbed region (misclassified samples): 2 % (docs/measurement.md,
// "Edges and circles"), and the 3σ rejection of the other robust fits (fit.hpp) for the
// midpoints' spread.
constexpr double kStabMissFraction = 0.02, kMidpointRejectK = 3.0;

}  // namespace

double cross_plane(const PlaneFit& pl, const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
    const double den = pl.normal.dot(d);
    return std::abs(den) < 1e-12 ? kNaN : pl.normal.dot(pl.point - o) / den;
}
// Nearest crossing of the ray with the cylinder r = radius about the part axis.
double cross_cylinder(double radius, const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
    const double a = d.x() * d.x() + d.y() * d.y();
    const double b = 2.0 * (o.x() * d.x() + o.y() * d.y());
    const double cc = o.x() * o.x() + o.y() * o.y() - radius * radius;
    const double disc = b * b - 4 * a * cc;
    if (a < 1e-15 || disc < 0) return kNaN;
    const double s1 = (-b - std::sqrt(disc)) / (2 * a);
    return s1 > 0 ? s1 : (-b + std::sqrt(disc)) / (2 * a);
}

std::optional<Eigen::Vector3d> grid_normal(const FaceFrame& fr, std::int64_t k, std::int64_t i) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
    int cnt = 0;
    for (std::int64_t dk = -kGridHalf; dk <= kGridHalf; ++dk)
        for (std::int64_t di = -kGridHalf; di <= kGridHalf; ++di) {
            if (!fr.valid(k + dk, i + di)) continue;
            const Eigen::Vector3d p = fr.point(k + dk, i + di);
            mean += p;
            S += p * p.transpose();
            ++cnt;
        }
    if (cnt < kMinNormalSamples) return std::nullopt;
    mean /= cnt;
    S = S / cnt - mean * mean.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(S);
    return es.eigenvectors().col(0);
}

PlaneSides::PlaneSides(const FaceFrame& fr, const PlaneFit& plane, double thr, std::int64_t k_lo,
                       std::int64_t k_hi, std::int64_t i_lo, std::int64_t i_hi)
    : fr_(fr),
      plane_(plane),
      thr_(thr),
      k0_(k_lo - kGridHalf),
      i0_(i_lo - kGridHalf),
      cols_(std::max<std::int64_t>(i_hi - i_lo + 1 + 2 * kGridHalf, 0)) {
    const std::int64_t rows = std::max<std::int64_t>(k_hi - k_lo + 1 + 2 * kGridHalf, 0);
    side_.assign(static_cast<std::size_t>(rows * cols_), Side::kUnknown);
}

PlaneSides::Side PlaneSides::side(std::int64_t k, std::int64_t i) {
    Side& s = side_[static_cast<std::size_t>((k - k0_) * cols_ + (i - i0_))];
    if (s == Side::kUnknown) {
        if (!fr_.valid(k, i)) {
            s = Side::kNone;
        } else {
            const double d = plane_.distance(fr_.point(k, i));
            s = d < -thr_ ? Side::kBelow : d > thr_ ? Side::kAbove : Side::kOn;
        }
    }
    return s;
}

// True when every valid sample of the 5×5 grid neighbourhood is on the plane: its normal is the
// plane's, no need to compute it.
bool PlaneSides::flat_around(std::int64_t k, std::int64_t i) {
    for (std::int64_t dk = -kGridHalf; dk <= kGridHalf; ++dk)
        for (std::int64_t di = -kGridHalf; di <= kGridHalf; ++di) {
            const Side s = side(k + dk, i + di);
            if (s == Side::kAbove || s == Side::kBelow) return false;
        }
    return true;
}

double sample_std(const std::vector<double>& v) {
    if (v.size() < 2) return kNaN;
    double m = 0;
    for (double x : v) m += x;
    m /= static_cast<double>(v.size());
    double s = 0;
    for (double x : v) s += (x - m) * (x - m);
    return std::sqrt(s / static_cast<double>(v.size() - 1));
}

MeanFit robust_mean(const std::vector<double>& v, double k_sigma) {
    MeanFit r;
    std::vector<std::uint8_t> in(v.size(), 1);
    for (int round = 0; round < kMeanRounds; ++round) {
        double s = 0, s2 = 0;
        std::int64_t n = 0;
        for (std::size_t j = 0; j < v.size(); ++j)
            if (in[j]) {
                s += v[j];
                s2 += v[j] * v[j];
                ++n;
            }
        if (n < 2) return r;
        r.mean = s / static_cast<double>(n);
        r.std = std::sqrt(std::max(0.0, s2 / static_cast<double>(n) - r.mean * r.mean));
        r.n = n;
        bool changed = false;
        for (std::size_t j = 0; j < v.size(); ++j) {
            const bool keep = std::abs(v[j] - r.mean) <= k_sigma * r.std + 1e-12;
            if (keep != static_cast<bool>(in[j])) {
                in[j] = keep;
                changed = true;
            }
        }
        if (!changed) break;
    }
    return r;
}

// Interval stabbing: the region at (nearly) full depth of the brackets' intervals.
IntervalEstimate stab(const std::vector<Interval>& iv) {
    IntervalEstimate e;
    if (iv.empty()) return e;
    std::vector<std::pair<double, int>> ev;
    std::vector<double> mids;
    for (const auto& v : iv) {
        ev.push_back({v.lo, +1});
        ev.push_back({v.hi, -1});
        mids.push_back(0.5 * (v.lo + v.hi));
    }
    std::sort(ev.begin(), ev.end(), [](auto& a, auto& b) {
        return a.first < b.first || (a.first == b.first && a.second > b.second);
    });
    int depth = 0, best = 0;
    for (const auto& [x, d] : ev) best = std::max(best, depth += d);
    // Tolerate a few brackets that miss (misclassified samples): the region at depth ≥ target.
    const int may_miss =
        std::max(1, static_cast<int>(kStabMissFraction * static_cast<double>(iv.size())));
    const int target = std::max(1, best - may_miss);
    double lo = kNaN, hi = kNaN, best_width = -1;
    depth = 0;
    double start = kNaN;
    for (const auto& [x, d] : ev) {
        const int before = depth;
        depth += d;
        if (before < target && depth >= target) start = x;
        if (before >= target && depth < target && x - start > best_width) {
            best_width = x - start;
            lo = start;
            hi = x;
        }
    }
    e.value = 0.5 * (lo + hi);
    e.u = (hi - lo) / std::sqrt(12.0);
    for (const auto& v : iv) e.n_used += v.lo <= hi && v.hi >= lo;
    e.midpoint_std = robust_mean(mids, kMidpointRejectK).std;
    return e;
}

namespace {

using BracketPair = std::pair<Eigen::Vector2d, Eigen::Vector2d>;

// By how much the circle of radius R misses a bracket whose ends lie ra and rb from its centre:
// 0 when it crosses it, negative when it passes inside both ends.
double bracket_miss(double R, double ra, double rb) {
    const double lo = std::min(ra, rb), hi = std::max(ra, rb);
    return R < lo ? R - lo : (R > hi ? R - hi : 0.0);
}
double bracket_miss(const Eigen::Vector3d& x, const BracketPair& b) {
    return bracket_miss(x.z(), (b.first - x.head<2>()).norm(), (b.second - x.head<2>()).norm());
}

// Gauss–Newton on the circle x = (centre, radius) over the brackets in use: their misses plus the
// midpoints' weak pull (weight wm), until the step is below a tenth of a nanometre.
void gauss_newton_brackets(const std::vector<BracketPair>& br, const std::vector<std::uint8_t>& use,
                           double wm, Eigen::Vector3d& x) {
    constexpr int kMaxIterations = 50;
    constexpr double kStepMm = 1e-10;
    for (int it = 0; it < kMaxIterations; ++it) {
        Eigen::Matrix3d JtJ = Eigen::Matrix3d::Zero();
        Eigen::Vector3d Jtr = Eigen::Vector3d::Zero();
        const Eigen::Vector2d c = x.head<2>();
        for (std::size_t q = 0; q < br.size(); ++q) {
            if (!use[q]) continue;
            const Eigen::Vector2d dA = br[q].first - c, dB = br[q].second - c;
            const Eigen::Vector2d dM = 0.5 * (dA + dB);
            const double ra = dA.norm(), rb = dB.norm(), rm = dM.norm();
            const double e = bracket_miss(x.z(), ra, rb);
            if (e != 0.0) {
                // d(R − r_X)/dc = +u_X (r_X decreases as c moves towards X)
                const Eigen::Vector2d u = ((e < 0) == (ra < rb) ? dA / ra : dB / rb);
                const Eigen::Vector3d J(u.x(), u.y(), 1.0);
                JtJ += J * J.transpose();
                Jtr += J * e;
            }
            const Eigen::Vector3d Jm(wm * dM.x() / rm, wm * dM.y() / rm, wm);
            JtJ += Jm * Jm.transpose();
            Jtr += Jm * (wm * (x.z() - rm));
        }
        const Eigen::Vector3d step = JtJ.ldlt().solve(-Jtr);
        if (!step.allFinite()) break;
        x += step;
        if (step.norm() < kStepMm) break;
    }
}

// Drops the brackets the circle x still misses by more than 3× their RMS miss (and at least
// min_miss_mm): misclassified samples. Returns whether any was dropped.
bool drop_missed_brackets(const std::vector<BracketPair>& br, const Eigen::Vector3d& x,
                          double min_miss_mm, std::vector<std::uint8_t>& use) {
    constexpr double kRejectK = 3.0;  // the 3σ rejection of the other robust fits (fit.hpp)
    double s2 = 0;
    std::int64_t n = 0;
    for (std::size_t q = 0; q < br.size(); ++q) {
        if (!use[q]) continue;
        const double e = bracket_miss(x, br[q]);
        s2 += e * e;
        ++n;
    }
    const double lim = std::max(
        kRejectK * std::sqrt(s2 / static_cast<double>(std::max<std::int64_t>(n, 1))), min_miss_mm);
    bool changed = false;
    for (std::size_t q = 0; q < br.size(); ++q) {
        if (!use[q]) continue;
        if (std::abs(bracket_miss(x, br[q])) > lim) {
            use[q] = 0;
            changed = true;
        }
    }
    return changed;
}

}  // namespace

// Circle through a set of brackets [A, B] (A on the surface, B beyond): each bracket holds the
// edge, so the circle should cross every segment. Minimises the squared distance by which the
// circle misses each bracket (zero inside), plus a weak pull (weight kMidpointPull) towards the
// midpoints that picks a point inside the feasible set; brackets that still miss by more than
// 3× the RMS miss are dropped and the fit repeated. Gauss–Newton from the midpoint circle.
BracketCircle fit_circle_brackets(const std::vector<BracketPair>& br, const Eigen::Vector2d& c0,
                                  double r0) {
    constexpr double kMidpointPull = 1e-4;  // weight² of the midpoint residuals
    // Brackets are exact to the ray geometry (µm); only a misclassified sample misses by more.
    constexpr double kMissLimitMm = 0.02;
    constexpr int kMaxRounds = 4;  // of fit and rejection
    const double wm = std::sqrt(kMidpointPull);
    Eigen::Vector3d x(c0.x(), c0.y(), r0);
    std::vector<std::uint8_t> use(br.size(), 1);
    for (int round = 0; round < kMaxRounds; ++round) {
        gauss_newton_brackets(br, use, wm, x);
        if (!drop_missed_brackets(br, x, kMissLimitMm, use)) break;
    }
    BracketCircle out{x.head<2>(), x.z(), 0};
    for (auto u : use) out.n_used += u;
    return out;
}

}  // namespace hotgauge::measure::detail
