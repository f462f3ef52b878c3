// Feature measurement on registered scans (docs/measurement.md). Planes: preselection by the
// known pose, RANSAC seed, least squares with iterative rejection (paper §4.3.1). Edges: coarse
// from local normals on the scan grid (paper §4.3.2), fine from the laser rays that bracket the
// edge: the edge lies between where two neighbouring rays cross the fitted surface, so the
// midpoint of those crossings is an unbiased edge sample (no "last point on the plane" bias).
// Circles: geometric least squares with rejection. Heights: parallel planes or edges along the
// axis. Thermal scaling to the cold equivalent.
#include "hotgauge/measure/features.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "hotgauge/core/parallel.hpp"
#include "hotgauge/measure/fit.hpp"

namespace hotgauge::measure {
namespace {

using core::AxisymmetricSolid;
using core::FeatureSpec;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kRadToDeg = 180.0 / std::numbers::pi;
// A pyrometer reading outside this is a fault, not a temperature (forging: 700–1300 °C).
constexpr double kMinTemperatureC = -50.0;
constexpr double kMaxTemperatureC = 1600.0;

// One face in the part frame. Any sample (profile k, column i) is transformed on demand; the
// samples near the part (inside its bounding cylinder, with a margin) are kept transformed and
// bucketed by z, so a query for a level or a z range visits only the samples near it. Each
// column has a ray model: in the camera frame its points lie on x = a_i + b_i·z (estimated
// from the data), so a sample without a return still has a known ray.
struct FaceFrame {
    const core::FaceScan* scan = nullptr;
    std::int64_t n = 0, w = 0;
    Eigen::Matrix3d M;                    // camera -> part rotation
    std::vector<Eigen::Vector3d> origin;  // per profile: camera origin in the part frame
    std::vector<double> col_a, col_b;
    Eigen::Vector3d view;  // camera +z (away from the sensor), part frame

    struct Near {
        std::int64_t q;     // k·w + i
        Eigen::Vector3f p;  // part frame
        float r;            // distance from the part axis
    };
    static constexpr double kBucketMm = 0.5;
    double z0 = 0;
    std::vector<Near> near;            // ordered by z bucket
    std::vector<std::int64_t> bucket;  // start of each bucket in `near`, plus an end sentinel

    // Calls f(const Near&) for the near-part samples with z in about [lo, hi] (whole buckets:
    // callers check exact bounds).
    template <class F>
    void for_z(double lo, double hi, F&& f) const {
        const auto nb = static_cast<std::int64_t>(bucket.size()) - 1;
        if (nb < 1 || hi < lo) return;
        const auto b0 = std::clamp<std::int64_t>(
            static_cast<std::int64_t>(std::floor((lo - z0) / kBucketMm)), 0, nb - 1);
        const auto b1 = std::clamp<std::int64_t>(
            static_cast<std::int64_t>(std::floor((hi - z0) / kBucketMm)), 0, nb - 1);
        for (std::int64_t j = bucket[b0]; j < bucket[b1 + 1]; ++j) f(near[j]);
    }

    bool valid(std::int64_t k, std::int64_t i) const {
        return k >= 0 && k < n && i >= 0 && i < w && std::isfinite(scan->x(k, i)) &&
               std::isfinite(scan->z(k, i));
    }
    Eigen::Vector3d point(std::int64_t k, std::int64_t i) const {
        return M * Eigen::Vector3d(scan->x(k, i), 0.0, scan->z(k, i)) + origin[k];
    }
    double radius(std::int64_t k, std::int64_t i) const {
        const Eigen::Vector3d p = point(k, i);
        return std::sqrt(p.x() * p.x() + p.y() * p.y());
    }
    double range(std::int64_t k, std::int64_t i) const { return scan->z(k, i); }
    // The ray of sample (k, i) as o + s·d, s = camera z.
    Eigen::Vector3d ray_origin(std::int64_t k, std::int64_t i) const {
        return origin[k] + M * Eigen::Vector3d(col_a[i], 0.0, 0.0);
    }
    Eigen::Vector3d ray_dir(std::int64_t i) const {
        return M * Eigen::Vector3d(col_b[i], 0.0, 1.0);
    }
};

// Per-column sums of the camera-frame samples, for the least-squares ray line x = a + b·z of
// each column. A sensor computes (x, z) from (column, row) through its calibration, so every
// sample of a column lies on that column's ray whatever it hit: one pass, no outliers to reject.
struct ColumnSums {
    double s = 0, sz = 0, sx = 0, szz = 0, szx = 0;
    void add(double x, double z) {
        s += 1;
        sz += z;
        sx += x;
        szz += z * z;
        szx += z * x;
    }
};

void fit_columns(const std::vector<ColumnSums>& sums, std::vector<double>& a,
                 std::vector<double>& b) {
    const auto w = static_cast<std::int64_t>(sums.size());
    a.assign(w, kNaN);
    b.assign(w, kNaN);
    std::vector<double> mean_x(w, kNaN), mean_z(w, kNaN);
    for (std::int64_t i = 0; i < w; ++i) {
        const ColumnSums& c = sums[i];
        if (c.s < 1) continue;
        mean_x[i] = c.sx / c.s;
        mean_z[i] = c.sz / c.s;
        const double var_z = c.szz / c.s - mean_z[i] * mean_z[i];
        if (c.s < 10 || var_z < 1.0) continue;  // too little depth spread to see the slope
        b[i] = (c.szx / c.s - mean_x[i] * mean_z[i]) / var_z;
        a[i] = mean_x[i] - b[i] * mean_z[i];
    }
    // Columns without a determined slope: interpolate the slope between determined neighbours
    // (the fan's slope varies smoothly across the line), keep their own mean point when any.
    std::vector<std::int64_t> known;
    for (std::int64_t i = 0; i < w; ++i)
        if (!std::isnan(b[i])) known.push_back(i);
    if (known.empty()) {
        for (std::int64_t i = 0; i < w; ++i) {  // no depth anywhere: rays through the origin
            b[i] = std::isnan(mean_z[i]) || mean_z[i] == 0 ? 0.0 : mean_x[i] / mean_z[i];
            a[i] = 0.0;
        }
        return;
    }
    std::size_t j = 0;
    for (std::int64_t i = 0; i < w; ++i) {
        if (!std::isnan(b[i])) continue;
        while (j + 1 < known.size() && known[j + 1] < i) ++j;
        const std::int64_t l = known[j], r = (j + 1 < known.size()) ? known[j + 1] : known[j];
        double bi, ai;
        if (i <= known.front()) {
            bi = b[known.front()];
            ai = a[known.front()];
        } else if (i >= known.back()) {
            bi = b[known.back()];
            ai = a[known.back()];
        } else {
            const double t = static_cast<double>(i - l) / static_cast<double>(r - l);
            bi = b[l] + t * (b[r] - b[l]);
            ai = a[l] + t * (a[r] - a[l]);
        }
        b[i] = bi;
        a[i] = std::isnan(mean_x[i]) ? ai : mean_x[i] - bi * mean_z[i];
    }
}

// A corrupt sample off its column's ray (which a calibrated sensor cannot produce) would tilt
// that column's line: columns with a sample farther than kRayToleranceMm from their line are
// fitted again from the samples near a robust (median) line.
void refit_off_ray_columns(const core::FaceScan& f, std::vector<ColumnSums>& sums,
                           std::vector<double>& a, std::vector<double>& b) {
    constexpr double kRayToleranceMm = 0.5;
    const std::int64_t n = f.n_profiles(), w = f.width;
    std::vector<std::uint8_t> bad(static_cast<std::size_t>(w), 0);
    bool any = false;
    for (std::int64_t k = 0; k < n; ++k)
        for (std::int64_t i = 0; i < w; ++i) {
            const double x = f.x(k, i), z = f.z(k, i);
            if (!std::isfinite(x) || !std::isfinite(z) || std::isnan(b[i])) continue;
            if (std::abs(x - a[i] - b[i] * z) > kRayToleranceMm) {
                bad[i] = 1;
                any = true;
            }
        }
    if (!any) return;
    for (std::int64_t i = 0; i < w; ++i) {
        if (!bad[i]) continue;
        std::vector<double> xs, zs, ratio, icpt;
        for (std::int64_t k = 0; k < n; ++k) {
            const double x = f.x(k, i), z = f.z(k, i);
            if (std::isfinite(x) && std::isfinite(z) && z != 0.0) {
                xs.push_back(x);
                zs.push_back(z);
                ratio.push_back(x / z);
            }
        }
        sums[i] = ColumnSums{};
        if (xs.empty()) continue;
        std::nth_element(ratio.begin(), ratio.begin() + ratio.size() / 2, ratio.end());
        const double b0 = ratio[ratio.size() / 2];
        for (std::size_t j = 0; j < xs.size(); ++j) icpt.push_back(xs[j] - b0 * zs[j]);
        std::nth_element(icpt.begin(), icpt.begin() + icpt.size() / 2, icpt.end());
        const double a0 = icpt[icpt.size() / 2];
        for (std::size_t j = 0; j < xs.size(); ++j)
            if (std::abs(xs[j] - a0 - b0 * zs[j]) <= kRayToleranceMm) sums[i].add(xs[j], zs[j]);
    }
    fit_columns(sums, a, b);
}

// Counting sort of the near-part samples by z bucket.
void bucket_by_z(FaceFrame& fr, std::vector<FaceFrame::Near> near, double z_lo, double z_hi) {
    const auto nb = static_cast<std::int64_t>((z_hi - z_lo) / FaceFrame::kBucketMm) + 1;
    fr.z0 = z_lo;
    auto index = [&](float z) {
        return std::clamp<std::int64_t>(
            static_cast<std::int64_t>((z - z_lo) / FaceFrame::kBucketMm), 0, nb - 1);
    };
    fr.bucket.assign(static_cast<std::size_t>(nb + 1), 0);
    for (const auto& s : near) ++fr.bucket[index(s.p.z()) + 1];
    for (std::int64_t b = 0; b < nb; ++b) fr.bucket[b + 1] += fr.bucket[b];
    fr.near.resize(near.size());
    std::vector<std::int64_t> fill(fr.bucket.begin(), fr.bucket.end() - 1);
    for (const auto& s : near) fr.near[fill[index(s.p.z())]++] = s;
}

// `r_max`, `z_lo`, `z_hi`: the part's bounding cylinder (hot, with margin), part frame.
FaceFrame make_frame(const core::FaceScan& f, const Eigen::Isometry3d& T_part_world,
                     const std::vector<Eigen::Vector3d>* u, double r_max, double z_lo,
                     double z_hi) {
    FaceFrame fr;
    fr.scan = &f;
    fr.n = f.n_profiles();
    fr.w = f.width;
    fr.M = T_part_world.linear() * f.T_world_camera.linear();
    fr.view = fr.M.col(2);
    fr.origin.resize(fr.n);
    std::vector<FaceFrame::Near> near;
    std::vector<ColumnSums> columns(static_cast<std::size_t>(fr.w));
    const double r2_max = r_max * r_max;
    for (std::int64_t k = 0; k < fr.n; ++k) {
        Eigen::Vector3d t =
            f.T_world_camera.translation() + f.profile_positions_mm[k] * f.scan_direction;
        if (u && static_cast<std::int64_t>(u->size()) == fr.n) t += (*u)[k];
        fr.origin[k] = T_part_world * t;
        for (std::int64_t i = 0; i < fr.w; ++i) {
            const float x = f.x(k, i), z = f.z(k, i);
            if (!std::isfinite(x) || !std::isfinite(z)) continue;
            columns[i].add(x, z);
            const Eigen::Vector3d p = fr.M * Eigen::Vector3d(x, 0.0, z) + fr.origin[k];
            const double r2 = p.x() * p.x() + p.y() * p.y();
            if (!(r2 <= r2_max && p.z() >= z_lo && p.z() <= z_hi)) continue;  // NaN-safe
            near.push_back({k * fr.w + i, p.cast<float>(), static_cast<float>(std::sqrt(r2))});
        }
    }
    fit_columns(columns, fr.col_a, fr.col_b);
    refit_off_ray_columns(f, columns, fr.col_a, fr.col_b);
    bucket_by_z(fr, std::move(near), z_lo, z_hi);
    return fr;
}

// Expected hot geometry: nominal × growth, and how much to widen windows for what is unknown.
struct Expect {
    double g = 1.0;      // growth used for expectations
    double slack = 0.0;  // relative uncertainty of g
    double z(double nominal) const { return nominal * g; }
    double tol(double base, double size) const { return base + std::abs(size) * g * slack; }
};

double surface_threshold(double rms, const MeasureConfig& c) {
    return std::max(c.on_surface_k_sigma * rms, c.on_surface_min_mm);
}

// Horizontal boundary pieces of the nominal solid at z, merged into contiguous r-intervals,
// with their outward normal (+1: material below, facing +z).
struct Annulus {
    double lo, hi;
    int facing;
};
std::vector<Annulus> annuli_at(const AxisymmetricSolid& s, double z) {
    std::vector<Annulus> out;
    std::vector<AxisymmetricSolid::Segment> segs;
    for (const auto& seg : s.boundary())
        if (!seg.cylinder && seg.value == z) segs.push_back(seg);
    std::sort(segs.begin(), segs.end(), [](auto& x, auto& y) { return x.lo < y.lo; });
    for (const auto& seg : segs) {
        const int facing = s.inside(0.5 * (seg.lo + seg.hi), z - 1e-6) ? +1 : -1;
        if (!out.empty() && out.back().hi == seg.lo && out.back().facing == facing)
            out.back().hi = seg.hi;
        else
            out.push_back({seg.lo, seg.hi, facing});
    }
    return out;
}

struct PlaneResult {
    PlaneFit fit;
    std::vector<Eigen::Vector3d> points;  // inliers
    std::string error;
};

// Least-squares plane of the annulus [r_lo, r_hi] at hot height z_e, from all given faces.
PlaneResult fit_level_plane(const std::vector<const FaceFrame*>& frames, double z_e, double band,
                            double r_lo, double r_hi, const MeasureConfig& c,
                            const std::string& what) {
    PlaneResult out;
    std::vector<Eigen::Vector3d> cand;
    for (const FaceFrame* fr : frames)
        fr->for_z(z_e - band, z_e + band, [&](const FaceFrame::Near& s) {
            if (std::abs(s.p.z() - z_e) <= band && s.r >= r_lo && s.r <= r_hi)
                cand.push_back(s.p.cast<double>());
        });
    if (static_cast<int>(cand.size()) < c.min_plane_points) {
        out.error =
            what + ": only " + std::to_string(cand.size()) + " points where the plane should be";
        return out;
    }
    // A plane is known to a fraction of a micrometre from tens of thousands of points: beyond
    // that, an even subsample keeps the fit's cost bounded.
    constexpr std::size_t kMaxPlanePoints = 20000;
    if (cand.size() > kMaxPlanePoints) {
        const std::size_t keep_every = (cand.size() + kMaxPlanePoints - 1) / kMaxPlanePoints;
        std::size_t m = 0;
        for (std::size_t q = 0; q < cand.size(); q += keep_every) cand[m++] = cand[q];
        cand.resize(m);
    }
    // RANSAC scores hypotheses on an even subsample (a few thousand points decide a plane as
    // well as a few hundred thousand); all candidates are then classified against its plane.
    constexpr std::size_t kRansacPoints = 4000;
    const double ransac_thr = std::max(c.on_surface_min_mm, 0.1);
    std::vector<Eigen::Vector3d> sub;
    const std::size_t stride = std::max<std::size_t>(1, cand.size() / kRansacPoints);
    for (std::size_t q = 0; q < cand.size(); q += stride) sub.push_back(cand[q]);
    auto seed = ransac_plane(sub, {ransac_thr, 100, 7});
    if (!seed) {
        out.error = what + ": " + seed.error().message;
        return out;
    }
    std::vector<Eigen::Vector3d> in;
    for (const auto& p : cand)
        if (std::abs(seed->fit.distance(p)) <= ransac_thr) in.push_back(p);
    auto fit = fit_plane_robust(in, {c.on_surface_k_sigma, 0.0, 10});
    if (!fit) {
        out.error = what + ": " + fit.error().message;
        return out;
    }
    for (std::size_t q = 0; q < in.size(); ++q)
        if (fit->inlier[q]) out.points.push_back(in[q]);
    out.fit = fit->fit;
    return out;
}

// Where the ray o + s·d crosses the plane; s is the camera range.
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

constexpr std::int64_t kNeighbours[4][2] = {{0, 1}, {0, -1}, {1, 0}, {-1, 0}};

// Edge samples between a surface and whatever lies beyond it. `on(k,i)` tells whether a sample
// is on the surface; `cross(k,i)` gives the range s where sample (k, i)'s ray meets the surface
// (NaN if it does not); `keep(A, B)` accepts a bracket by position (side, window). The edge lies
// between the two rays' crossings A (last sample on the surface) and B (first one beyond).
struct Bracket {
    Eigen::Vector3d A, B;
};
template <class On, class Cross, class Keep>
std::vector<Bracket> bracket_edges(const FaceFrame& fr, const std::vector<std::int64_t>& seeds,
                                   double thr, double max_gap, On on, Cross cross, Keep keep) {
    std::vector<Bracket> out;
    for (std::int64_t q : seeds) {
        const std::int64_t k = q / fr.w, i = q % fr.w;
        for (const auto& nb : kNeighbours) {
            const std::int64_t kb = k + nb[0], ib = i + nb[1];
            if (kb < 0 || kb >= fr.n || ib < 0 || ib >= fr.w) continue;
            const double sb = cross(kb, ib);
            if (std::isnan(sb)) continue;
            // Beyond the edge: no return, or a return farther from the sensor than the surface.
            auto beyond = [&](std::int64_t kk, std::int64_t ii, double s_surface) {
                if (kk < 0 || kk >= fr.n || ii < 0 || ii >= fr.w || !fr.valid(kk, ii)) return true;
                return !on(kk, ii) && fr.range(kk, ii) > s_surface + thr;
            };
            if (!beyond(kb, ib, sb)) continue;
            if (!fr.valid(kb, ib)) {
                // A lone dropout on the surface is not an edge: the sample after it must be
                // beyond as well.
                const std::int64_t kc = kb + nb[0], ic = ib + nb[1];
                if (kc >= 0 && kc < fr.n && ic >= 0 && ic < fr.w) {
                    const double sc = cross(kc, ic);
                    if (std::isnan(sc) || !beyond(kc, ic, sc)) continue;
                }
            }
            const double sa = cross(k, i);
            if (std::isnan(sa)) continue;
            const Eigen::Vector3d A = fr.ray_origin(k, i) + sa * fr.ray_dir(i);
            const Eigen::Vector3d B = fr.ray_origin(kb, ib) + sb * fr.ray_dir(ib);
            if ((A - B).norm() > max_gap || !keep(A, B)) continue;
            out.push_back({A, B});
        }
    }
    return out;
}

// Local normal from the scan grid neighbourhood (±2 profiles × ±2 columns): the organised scan
// gives neighbours for free, no k-d tree needed.
std::optional<Eigen::Vector3d> grid_normal(const FaceFrame& fr, std::int64_t k, std::int64_t i) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
    int cnt = 0;
    for (std::int64_t dk = -2; dk <= 2; ++dk)
        for (std::int64_t di = -2; di <= 2; ++di) {
            if (!fr.valid(k + dk, i + di)) continue;
            const Eigen::Vector3d p = fr.point(k + dk, i + di);
            mean += p;
            S += p * p.transpose();
            ++cnt;
        }
    if (cnt < 6) return std::nullopt;
    mean /= cnt;
    S = S / cnt - mean * mean.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(S);
    return es.eigenvectors().col(0);
}

// True when every valid sample of the 5×5 grid neighbourhood is on the plane: its normal is the
// plane's, no need to compute it.
bool flat_around(const FaceFrame& fr, const PlaneFit& plane, double thr, std::int64_t k,
                 std::int64_t i) {
    for (std::int64_t dk = -2; dk <= 2; ++dk)
        for (std::int64_t di = -2; di <= 2; ++di)
            if (fr.valid(k + dk, i + di) &&
                std::abs(plane.distance(fr.point(k + dk, i + di))) > thr)
                return false;
    return true;
}

double angle_of(const Eigen::Vector2d& v) { return std::atan2(v.y(), v.x()); }

double sample_std(const std::vector<double>& v) {
    if (v.size() < 2) return kNaN;
    double m = 0;
    for (double x : v) m += x;
    m /= static_cast<double>(v.size());
    double s = 0;
    for (double x : v) s += (x - m) * (x - m);
    return std::sqrt(s / static_cast<double>(v.size() - 1));
}

// Iterative k·σ rejection around the mean; returns mean, std, count.
struct MeanFit {
    double mean = kNaN, std = kNaN;
    std::int64_t n = 0;
};
MeanFit robust_mean(const std::vector<double>& v, double k_sigma) {
    MeanFit r;
    std::vector<std::uint8_t> in(v.size(), 1);
    for (int round = 0; round < 10; ++round) {
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

// The edge as the coordinate most brackets agree on (interval stabbing). Every bracket contains
// the true edge up to the ray and surface errors (µm), so where brackets are not dithered across
// the sampling grid (a straight edge seen by fixed rays) their intersection pins the edge far
// better than the mean of midpoints, whose error would be up to half a spacing.
struct Interval {
    double lo, hi;
};
struct IntervalEstimate {
    double value = kNaN;
    double u = kNaN;             // standard uncertainty: width of the agreed region / √12
    double midpoint_std = kNaN;  // spread of the bracket midpoints (the sampling's own scatter)
    std::int64_t n_used = 0;     // brackets containing the agreed region
};
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
    const int target =
        std::max(1, best - std::max(1, static_cast<int>(0.02 * static_cast<double>(iv.size()))));
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
    e.midpoint_std = robust_mean(mids, 3.0).std;
    return e;
}

// Circle through a set of brackets [A, B] (A on the surface, B beyond): each bracket holds the
// edge, so the circle should cross every segment. Minimises the squared distance by which the
// circle misses each bracket (zero inside), plus a weak pull (weight kMidpointPull) towards the
// midpoints that picks a point inside the feasible set; brackets that still miss by more than
// 3× the RMS miss are dropped and the fit repeated. Gauss–Newton from the midpoint circle.
struct BracketCircle {
    Eigen::Vector2d center;
    double radius = 0;
    std::int64_t n_used = 0;
};
BracketCircle fit_circle_brackets(
    const std::vector<std::pair<Eigen::Vector2d, Eigen::Vector2d>>& br, const Eigen::Vector2d& c0,
    double r0) {
    constexpr double kMidpointPull = 1e-4;  // weight² of the midpoint residuals
    // Brackets are exact to the ray geometry (µm); only a misclassified sample misses by more.
    constexpr double kMissLimitMm = 0.02;
    const double wm = std::sqrt(kMidpointPull);
    Eigen::Vector3d x(c0.x(), c0.y(), r0);
    std::vector<std::uint8_t> use(br.size(), 1);
    auto miss = [](double R, double ra, double rb) {
        const double lo = std::min(ra, rb), hi = std::max(ra, rb);
        return R < lo ? R - lo : (R > hi ? R - hi : 0.0);
    };
    for (int round = 0; round < 4; ++round) {
        for (int it = 0; it < 50; ++it) {
            Eigen::Matrix3d JtJ = Eigen::Matrix3d::Zero();
            Eigen::Vector3d Jtr = Eigen::Vector3d::Zero();
            const Eigen::Vector2d c = x.head<2>();
            for (std::size_t q = 0; q < br.size(); ++q) {
                if (!use[q]) continue;
                const Eigen::Vector2d dA = br[q].first - c, dB = br[q].second - c;
                const Eigen::Vector2d dM = 0.5 * (dA + dB);
                const double ra = dA.norm(), rb = dB.norm(), rm = dM.norm();
                const double e = miss(x.z(), ra, rb);
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
            if (step.norm() < 1e-10) break;
        }
        // Drop brackets the circle still misses by far (misclassified samples).
        double s2 = 0;
        std::int64_t n = 0;
        for (std::size_t q = 0; q < br.size(); ++q) {
            if (!use[q]) continue;
            const double e = miss(x.z(), (br[q].first - x.head<2>()).norm(),
                                  (br[q].second - x.head<2>()).norm());
            s2 += e * e;
            ++n;
        }
        const double lim = std::max(
            3.0 * std::sqrt(s2 / static_cast<double>(std::max<std::int64_t>(n, 1))), kMissLimitMm);
        bool changed = false;
        for (std::size_t q = 0; q < br.size(); ++q) {
            if (!use[q]) continue;
            const double e = miss(x.z(), (br[q].first - x.head<2>()).norm(),
                                  (br[q].second - x.head<2>()).norm());
            if (std::abs(e) > lim) {
                use[q] = 0;
                changed = true;
            }
        }
        if (!changed) break;
    }
    BracketCircle out{x.head<2>(), x.z(), 0};
    for (auto u : use) out.n_used += u;
    return out;
}

class FeatureMeasurer {
  public:
    FeatureMeasurer(const core::Recipe& recipe, const std::map<std::string, FaceFrame>& frames,
                    const Expect& expect, const MeasureConfig& c)
        : recipe_(recipe),
          solid_(AxisymmetricSolid::from_recipe(recipe)),
          frames_(frames),
          ex_(expect),
          c_(c) {}

    void measure(const FeatureSpec& f, FeatureResult& r) {
        std::vector<const FaceFrame*> frames;
        for (const auto& name : f.faces) {
            auto it = frames_.find(name);
            if (it == frames_.end()) {
                r.reason = "face '" + name + "' is not in the recording";
                return;
            }
            frames.push_back(&it->second);
        }
        if (f.kind == core::FeatureKind::kDiameter)
            diameter(f, frames, r);
        else if (f.height_method == core::HeightMethod::kPlanes)
            height_planes(f, frames, r);
        else
            height_edges(f, frames, r);
    }

  private:
    // Facing every face's sensor: the annulus's outward normal points against each view.
    static bool faces_sensors(const Annulus& a, const std::vector<const FaceFrame*>& frames) {
        for (const auto* fr : frames)
            if (a.facing * fr->view.z() >= 0) return false;
        return true;
    }

    // The visible annulus at `level` next to radius R (nominal, cold), or an error.
    std::optional<Annulus> annulus(const std::string& level, double R,
                                   const std::vector<const FaceFrame*>& frames, std::string& why) {
        const double z = *recipe_.level(level);
        for (const auto& a : annuli_at(solid_, z)) {
            if (a.lo != R && a.hi != R) continue;
            if (!faces_sensors(a, frames)) {
                why = "the face at level '" + level + "' does not face the sensor of " +
                      frames.front()->scan->name;
                continue;
            }
            return a;
        }
        if (why.empty()) why = "no flat face at level '" + level + "' next to the edge";
        return std::nullopt;
    }

    PlaneResult level_plane(const std::string& level, const Annulus& a,
                            const std::vector<const FaceFrame*>& frames) {
        const double z = *recipe_.level(level);
        const double m = c_.support_margin_mm;
        PlaneResult pl = fit_level_plane(
            frames, ex_.z(z), ex_.tol(c_.plane_band_mm, z), ex_.z(a.lo) + ex_.tol(m, a.lo),
            ex_.z(a.hi) - ex_.tol(m, a.hi), c_, "plane at level '" + level + "'");
        if (pl.error.empty()) {
            const double tilt = std::acos(std::min(1.0, std::abs(pl.fit.normal.z()))) * kRadToDeg;
            if (tilt > c_.max_plane_tilt_deg)
                pl.error = "plane at level '" + level + "' is tilted " + std::to_string(tilt) +
                           "° from the part axis: wrong pose or wrong part";
        }
        return pl;
    }

    void diameter(const FeatureSpec& f, const std::vector<const FaceFrame*>& frames,
                  FeatureResult& r) {
        const core::Section& sec = *recipe_.section(f.section);
        const double R = 0.5 * sec.diameter_mm;
        std::string why;
        const auto ann = annulus(f.edge_at, R, frames, why);
        if (!ann) {
            r.reason = why;
            return;
        }
        const bool plane_inside = ann->hi == R;  // the plane lies at r < R (outer edge)
        PlaneResult pl = level_plane(f.edge_at, *ann, frames);
        if (!pl.error.empty()) {
            r.reason = pl.error;
            return;
        }
        PlaneFit plane = pl.fit;
        // Orient the plane's normal towards the sensor.
        if (plane.normal.dot(frames.front()->view) > 0) plane.normal = -plane.normal;
        const double thr = surface_threshold(plane.rms_mm, c_);
        const double R_e = ex_.z(R), win = ex_.tol(c_.edge_window_mm, R);

        // In-plane 2D frame for circle fitting.
        const Eigen::Vector3d e1 = plane.normal.unitOrthogonal(), e2 = plane.normal.cross(e1);
        auto to2d = [&](const Eigen::Vector3d& p) {
            const Eigen::Vector3d d = p - plane.point;
            return Eigen::Vector2d(d.dot(e1), d.dot(e2));
        };

        // Coarse edge: on-plane samples near the edge whose grid normal leaves the plane normal
        // (paper §4.3.2) or that border the region beyond the edge.
        std::vector<Eigen::Vector2d> coarse;
        std::vector<std::vector<std::int64_t>> seeds(frames.size());
        const double cos_edge = std::cos(c_.normal_edge_deg / kRadToDeg);
        for (std::size_t fi = 0; fi < frames.size(); ++fi) {
            const FaceFrame& fr = *frames[fi];
            // On-plane samples lie within the plane's preselection band of its level.
            const double band = ex_.tol(c_.plane_band_mm, *recipe_.level(f.edge_at));
            fr.for_z(plane.point.z() - band, plane.point.z() + band, [&](const FaceFrame::Near& s) {
                if (std::abs(s.r - R_e) > win) return;
                const std::int64_t q = s.q;
                const Eigen::Vector3d p = s.p.cast<double>();
                if (std::abs(plane.distance(p)) > thr) return;
                seeds[fi].push_back(q);
                const std::int64_t k = q / fr.w, i = q % fr.w;
                // A neighbour beyond: no return, or farther from the sensor than the plane.
                bool edge = false;
                for (const auto& nb : kNeighbours)
                    if (!fr.valid(k + nb[0], i + nb[1]) ||
                        plane.distance(fr.point(k + nb[0], i + nb[1])) < -thr)
                        edge = true;
                if (!edge && !flat_around(fr, plane, thr, k, i)) {
                    const auto nrm = grid_normal(fr, k, i);
                    edge = nrm && std::abs(nrm->dot(plane.normal)) < cos_edge;
                }
                if (edge) coarse.push_back(to2d(p));
            });
        }
        if (static_cast<int>(coarse.size()) < c_.min_edge_points) {
            r.reason = "edge of '" + f.section + "' at '" + f.edge_at + "': only " +
                       std::to_string(coarse.size()) + " edge points near the expected radius";
            return;
        }
        auto coarse_fit = fit_circle_robust(coarse, {3.0, 0.1, 10});
        if (!coarse_fit) {
            r.reason = "coarse edge circle: " + coarse_fit.error().message;
            return;
        }

        // Fine edge: midpoints of the ray crossings that bracket the edge; a first pass in a wide
        // window around the coarse circle, a second one close to the first pass's circle.
        std::vector<Eigen::Vector2d> fine;
        std::vector<std::pair<Eigen::Vector2d, Eigen::Vector2d>> fine_brackets;
        Eigen::Vector2d cc = coarse_fit->fit.center;
        double rc = coarse_fit->fit.radius, window = c_.fine_window_mm;
        std::optional<RobustCircleFit> fit;
        for (int pass = 0; pass < 2; ++pass) {
            fine.clear();
            fine_brackets.clear();
            for (std::size_t fi = 0; fi < frames.size(); ++fi) {
                const FaceFrame& fr = *frames[fi];
                auto on = [&](std::int64_t k, std::int64_t i) {
                    return std::abs(plane.distance(fr.point(k, i))) <= thr;
                };
                auto cross = [&](std::int64_t k, std::int64_t i) {
                    return cross_plane(plane, fr.ray_origin(k, i), fr.ray_dir(i));
                };
                auto keep = [&](const Eigen::Vector3d& A, const Eigen::Vector3d& B) {
                    const double ra = (to2d(A) - cc).norm(), rb = (to2d(B) - cc).norm();
                    const double rm = (to2d(0.5 * (A + B)) - cc).norm();
                    return (plane_inside ? ra < rb : ra > rb) && std::abs(rm - rc) <= window;
                };
                for (const auto& b :
                     bracket_edges(fr, seeds[fi], thr, c_.max_pair_gap_mm, on, cross, keep)) {
                    fine.push_back(to2d(0.5 * (b.A + b.B)));
                    fine_brackets.emplace_back(to2d(b.A), to2d(b.B));
                }
            }
            if (static_cast<int>(fine.size()) < c_.min_edge_points) {
                r.reason = "edge of '" + f.section + "': only " + std::to_string(fine.size()) +
                           " bracketed edge samples";
                return;
            }
            auto pass_fit = fit_circle_robust(fine, {3.0, 0.02, 10});
            if (!pass_fit) {
                r.reason = "edge circle: " + pass_fit.error().message;
                return;
            }
            fit = std::move(*pass_fit);
            cc = fit->fit.center;
            rc = fit->fit.radius;
            window = c_.refine_window_mm;
        }
        // Coverage and sectors (multiple sampling).
        std::vector<int> bins(36, 0);
        const int ns = std::max(1, c_.sectors);
        std::vector<double> ssum(ns, 0.0);
        std::vector<int> scnt(ns, 0);
        for (std::size_t q = 0; q < fine.size(); ++q) {
            if (!fit->inlier[q]) continue;
            const Eigen::Vector2d d = fine[q] - fit->fit.center;
            const double ang = angle_of(d) + std::numbers::pi;  // [0, 2π]
            bins[std::min(35, static_cast<int>(ang / (2 * std::numbers::pi) * 36))]++;
            const int s = std::min(ns - 1, static_cast<int>(ang / (2 * std::numbers::pi) * ns));
            ssum[s] += d.norm();
            scnt[s]++;
        }
        int covered = 0;
        for (int b : bins) covered += b > 0;
        r.arc_deg = 10.0 * covered;
        if (r.arc_deg < c_.min_arc_deg) {
            r.reason =
                "edge seen on only " + std::to_string(static_cast<int>(r.arc_deg)) + "° of arc";
            return;
        }
        std::vector<double> sector_d;
        const int min_in_sector = std::max(5, static_cast<int>(fit->fit.n_points / (4 * ns)));
        for (int s = 0; s < ns; ++s)
            if (scnt[s] >= min_in_sector) sector_d.push_back(2.0 * ssum[s] / scnt[s]);
        // The midpoint fit is unbiased only where the edge is dithered across the sampling grid;
        // the bracket fit keeps the circle inside every bracket and so removes what is left.
        std::vector<std::pair<Eigen::Vector2d, Eigen::Vector2d>> inlier_brackets;
        for (std::size_t q = 0; q < fine.size(); ++q)
            if (fit->inlier[q]) inlier_brackets.push_back(fine_brackets[q]);
        const BracketCircle bc =
            fit_circle_brackets(inlier_brackets, fit->fit.center, fit->fit.radius);
        // The circle's centre must lie on the part axis (the pose put it there) and its radius in
        // the window: otherwise these are not the edge's points.
        const Eigen::Vector3d centre = plane.point + bc.center.x() * e1 + bc.center.y() * e2;
        const double off_axis = centre.head<2>().norm();
        if (off_axis > c_.max_axis_offset_mm || std::abs(bc.radius - R_e) > win) {
            r.reason = "edge circle of '" + f.section + "' is " + std::to_string(off_axis) +
                       " mm off the part axis, radius " + std::to_string(bc.radius) +
                       " mm: wrong pose or wrong part";
            return;
        }
        r.fit_rms_mm = fit->fit.rms_mm;
        r.n_points = fit->fit.n_points;
        if (r.arc_deg >= c_.free_centre_min_arc_deg) {
            r.hot_mm = 2.0 * bc.radius;
            // Conservative: the statistical figure of the midpoint fit, plus how far the bracket
            // constraints had to move it (the sampling grid's share).
            r.u_mm = 2.0 * std::hypot(fit->fit.u_radius_mm, bc.radius - fit->fit.radius);
        } else {
            // On a partial arc the centre and the radius trade off (the arc's chord direction is
            // weakly determined): take the centre from the part axis, which the pose gives for
            // every feature at once, and the radius as the one all brackets agree on around it.
            const double z_axis = plane.point.z() + (plane.normal.x() * plane.point.x() +
                                                     plane.normal.y() * plane.point.y()) /
                                                        plane.normal.z();
            const Eigen::Vector2d c_axis = to2d(Eigen::Vector3d(0.0, 0.0, z_axis));
            std::vector<Interval> radial;
            for (const auto& [A, B] : inlier_brackets) {
                const double ra = (A - c_axis).norm(), rb = (B - c_axis).norm();
                radial.push_back({std::min(ra, rb), std::max(ra, rb)});
            }
            const IntervalEstimate e = stab(radial);
            // The free fit's disagreement carries the pose's axis error: it enters u in full, and
            // beyond what the free fit's own noise explains the value is not trusted at all.
            const double disagreement = std::abs(e.value - bc.radius);
            const double limit =
                std::max(c_.max_partial_arc_disagreement_mm, 3.0 * fit->fit.u_radius_mm);
            if (disagreement > limit) {
                r.reason = "edge of '" + f.section + "' on " +
                           std::to_string(static_cast<int>(r.arc_deg)) +
                           "° of arc: centred on the part axis its radius differs by " +
                           std::to_string(disagreement) +
                           " mm from a free fit: pose off or edge distorted";
                return;
            }
            r.hot_mm = 2.0 * e.value;
            r.u_mm = 2.0 * std::hypot(e.u, disagreement);
        }
        r.n_sectors = static_cast<int>(sector_d.size());
        if (sector_d.size() >= 2) r.sector_spread_mm = sample_std(sector_d);
    }

    void height_planes(const FeatureSpec& f, const std::vector<const FaceFrame*>& frames,
                       FeatureResult& r) {
        PlaneResult pl[2];
        const std::string levels[2] = {f.from_level, f.to_level};
        for (int j = 0; j < 2; ++j) {
            // The widest visible annulus at the level.
            std::optional<Annulus> best;
            const double z = *recipe_.level(levels[j]);
            for (const auto& a : annuli_at(solid_, z))
                if (faces_sensors(a, frames) && (!best || a.hi - a.lo > best->hi - best->lo))
                    best = a;
            if (!best) {
                r.reason = "no flat face at level '" + levels[j] + "' facing the sensor";
                return;
            }
            pl[j] = level_plane(levels[j], *best, frames);
            if (!pl[j].error.empty()) {
                r.reason = pl[j].error;
                return;
            }
        }
        const PlaneFit &A = pl[0].fit, &B = pl[1].fit;
        // Distance of one plane's centroid from the other, measured along the normal of the
        // better-supported plane: a narrow or partial annulus (a bore step seen through the
        // bore) has a poorly known tilt, and its centroid sits off the axis.
        const bool a_ref = A.n_points >= B.n_points;
        const double h = a_ref ? std::abs(A.distance(B.point)) : std::abs(B.distance(A.point));
        r.hot_mm = h;
        r.fit_rms_mm = std::max(A.rms_mm, B.rms_mm);
        r.n_points = A.n_points + B.n_points;
        r.u_mm = std::sqrt(A.rms_mm * A.rms_mm / static_cast<double>(A.n_points) +
                           B.rms_mm * B.rms_mm / static_cast<double>(B.n_points));
        // Sectors: the height from the points of each angular sector of both planes.
        const int ns = std::max(1, c_.sectors);
        std::vector<double> sa(ns, 0), sb(ns, 0);
        std::vector<int> na(ns, 0), nb(ns, 0);
        auto sector = [&](const Eigen::Vector3d& p) {
            const double ang = std::atan2(p.y(), p.x()) + std::numbers::pi;
            return std::min(ns - 1, static_cast<int>(ang / (2 * std::numbers::pi) * ns));
        };
        for (const auto& p : pl[0].points) {
            sa[sector(p)] += A.distance(p);
            na[sector(p)]++;
        }
        for (const auto& p : pl[1].points) {
            sb[sector(p)] += A.distance(p);
            nb[sector(p)]++;
        }
        std::vector<double> hs;
        for (int s = 0; s < ns; ++s)
            if (na[s] >= 10 && nb[s] >= 10) hs.push_back(std::abs(sb[s] / nb[s] - sa[s] / na[s]));
        r.n_sectors = static_cast<int>(hs.size());
        if (hs.size() >= 2) r.sector_spread_mm = sample_std(hs);
    }

    // Axial position of the convex edge at `level` seen from the side: where the outermost wall
    // ending at that level ends. Returns the brackets as z intervals (hot, part frame) and the
    // angle about the axis where each was seen.
    bool wall_edge(const std::string& level, const std::vector<const FaceFrame*>& frames,
                   std::vector<Interval>& zs, std::vector<double>& angles, std::string& why) {
        const double L = *recipe_.level(level);
        const AxisymmetricSolid::Segment* wall = nullptr;
        for (const auto& s : solid_.boundary())
            if (s.cylinder && (s.lo == L || s.hi == L) &&
                solid_.inside(s.value - 1e-6, 0.5 * (s.lo + s.hi)) &&
                (!wall || s.value > wall->value))
                wall = &s;
        if (!wall) {
            why = "no outer wall ends at level '" + level + "'";
            return false;
        }
        const bool wall_below = wall->hi == L;
        const double R_e = ex_.z(wall->value), band = ex_.tol(c_.wall_band_mm, wall->value);
        const double m = c_.support_margin_mm;
        const double z_lo = ex_.z(wall->lo) + ex_.tol(m, wall->lo),
                     z_hi = ex_.z(wall->hi) - ex_.tol(m, wall->hi);
        // Wall radius about the part axis (the pose gives the axis).
        std::vector<double> radii;
        for (const auto* fr : frames)
            fr->for_z(z_lo, z_hi, [&](const FaceFrame::Near& s) {
                if (s.p.z() >= z_lo && s.p.z() <= z_hi && std::abs(s.r - R_e) <= band)
                    radii.push_back(s.r);
            });
        if (static_cast<int>(radii.size()) < c_.min_plane_points) {
            why = "wall at level '" + level + "': only " + std::to_string(radii.size()) + " points";
            return false;
        }
        const MeanFit rw = robust_mean(radii, 3.0);
        const double thr = surface_threshold(rw.std, c_);
        const double L_e = ex_.z(L), win = ex_.tol(c_.edge_window_mm, L);
        for (const auto* frp : frames) {
            const FaceFrame& fr = *frp;
            std::vector<std::int64_t> seeds;
            auto on = [&](std::int64_t k, std::int64_t i) {
                return std::abs(fr.radius(k, i) - rw.mean) <= thr;
            };
            fr.for_z(L_e - win, L_e + win, [&](const FaceFrame::Near& s) {
                const std::int64_t q = s.q;
                if (std::abs(s.p.z() - L_e) <= win && std::abs(s.r - rw.mean) <= thr)
                    seeds.push_back(q);
            });
            auto cross = [&](std::int64_t k, std::int64_t i) {
                return cross_cylinder(rw.mean, fr.ray_origin(k, i), fr.ray_dir(i));
            };
            auto keep = [&](const Eigen::Vector3d& A, const Eigen::Vector3d& B) {
                return wall_below ? A.z() < B.z() : A.z() > B.z();
            };
            for (const auto& b :
                 bracket_edges(fr, seeds, thr, c_.max_pair_gap_mm, on, cross, keep)) {
                zs.push_back({std::min(b.A.z(), b.B.z()), std::max(b.A.z(), b.B.z())});
                angles.push_back(std::atan2(b.A.y(), b.A.x()));
            }
        }
        if (static_cast<int>(zs.size()) < c_.min_edge_points) {
            why = "edge at level '" + level + "': only " + std::to_string(zs.size()) +
                  " edge samples";
            return false;
        }
        return true;
    }

    void height_edges(const FeatureSpec& f, const std::vector<const FaceFrame*>& frames,
                      FeatureResult& r) {
        std::vector<Interval> iv[2];
        std::vector<double> ang[2];
        const std::string levels[2] = {f.from_level, f.to_level};
        IntervalEstimate e[2];
        for (int j = 0; j < 2; ++j) {
            if (!wall_edge(levels[j], frames, iv[j], ang[j], r.reason)) return;
            e[j] = stab(iv[j]);
        }
        r.reason.clear();
        r.hot_mm = std::abs(e[1].value - e[0].value);
        r.fit_rms_mm = std::max(e[0].midpoint_std, e[1].midpoint_std);
        r.n_points = e[0].n_used + e[1].n_used;
        r.u_mm = std::hypot(e[0].u, e[1].u);
        // Sectors: the same estimate on each part of the observed angular span.
        double lo = std::numeric_limits<double>::max(), hi = std::numeric_limits<double>::lowest();
        for (int j = 0; j < 2; ++j)
            for (double a : ang[j]) {
                lo = std::min(lo, a);
                hi = std::max(hi, a);
            }
        const int ns = std::max(1, c_.sectors / 2);
        std::vector<double> hs;
        for (int sec = 0; sec < ns; ++sec) {
            std::vector<Interval> part[2];
            for (int j = 0; j < 2; ++j)
                for (std::size_t q = 0; q < iv[j].size(); ++q)
                    if (std::min(ns - 1, static_cast<int>((ang[j][q] - lo) / (hi - lo + 1e-12) *
                                                          ns)) == sec)
                        part[j].push_back(iv[j][q]);
            if (part[0].size() < 10 || part[1].size() < 10) continue;
            hs.push_back(std::abs(stab(part[1]).value - stab(part[0]).value));
        }
        r.n_sectors = static_cast<int>(hs.size());
        if (hs.size() >= 2) r.sector_spread_mm = sample_std(hs);
    }

    const core::Recipe& recipe_;
    AxisymmetricSolid solid_;
    const std::map<std::string, FaceFrame>& frames_;
    Expect ex_;
    MeasureConfig c_;
};

FeatureResult skeleton(const FeatureSpec& f) {
    FeatureResult r;
    r.name = f.name;
    r.kind = f.kind;
    r.slot = f.slot;
    r.faces = f.faces;
    r.nominal_mm = f.nominal_mm;
    r.tol_lower_mm = f.tol_lower_mm;
    r.tol_upper_mm = f.tol_upper_mm;
    return r;
}

Verdict overall(const std::vector<FeatureResult>& features) {
    bool any_not = features.empty();
    for (const auto& f : features) {
        if (f.verdict == Verdict::kNok) return Verdict::kNok;
        any_not = any_not || f.verdict == Verdict::kNotMeasured;
    }
    return any_not ? Verdict::kNotMeasured : Verdict::kOk;
}

}  // namespace

const char* to_string(Verdict v) {
    switch (v) {
        case Verdict::kOk:
            return "OK";
        case Verdict::kNok:
            return "NOK";
        case Verdict::kNotMeasured:
            return "NOT_MEASURED";
    }
    return "NOT_MEASURED";
}

PartMeasurement unmeasured(const core::Recipe& recipe, const core::Recording& rec,
                           const std::string& reason) {
    PartMeasurement out;
    out.temperature_c = rec.temperature_c;
    if (rec.temperature_c && *rec.temperature_c >= kMinTemperatureC &&
        *rec.temperature_c <= kMaxTemperatureC)
        out.growth = recipe.material.growth(*rec.temperature_c);
    for (const auto& f : recipe.features) {
        out.features.push_back(skeleton(f));
        out.features.back().reason = reason;
    }
    out.verdict = Verdict::kNotMeasured;
    return out;
}

PartMeasurement measure_part(const core::Recipe& recipe, const core::Recording& rec,
                             const Eigen::Isometry3d& T_world_part, const FaceDisplacements& u,
                             const MeasureConfig& config) {
    PartMeasurement out;
    out.temperature_c = rec.temperature_c;
    Expect ex;
    const bool plausible_t = rec.temperature_c && *rec.temperature_c >= kMinTemperatureC &&
                             *rec.temperature_c <= kMaxTemperatureC;
    if (plausible_t) {
        out.growth = recipe.material.growth(*rec.temperature_c);
        ex.g = *out.growth;
        ex.slack = 0.002;  // α model error
    } else {
        ex.g = 1.0 + 0.5 * config.unknown_growth;
        ex.slack = 0.5 * config.unknown_growth;
    }
    const Eigen::Isometry3d T_part_world = T_world_part.inverse();
    // The part's bounding cylinder, hot, with room for an unknown temperature and edge windows.
    const AxisymmetricSolid nominal = AxisymmetricSolid::from_recipe(recipe);
    double z_min = 0.0, z_max = 0.0;
    for (const auto& [name, z] : recipe.levels_mm) {
        z_min = std::min(z_min, z);
        z_max = std::max(z_max, z);
    }
    const double margin = 5.0;
    const double gmax = ex.g * (1.0 + ex.slack);
    // Faces, then features, are independent of each other: spread over the cores.
    std::vector<FaceFrame> prepared(rec.faces.size());
    core::parallel_for(rec.faces.size(), config.threads, [&](std::size_t i, unsigned) {
        const auto& face = rec.faces[i];
        auto it = u.find(face.name);
        prepared[i] =
            make_frame(face, T_part_world, it == u.end() ? nullptr : &it->second,
                       nominal.max_radius() * gmax + margin, std::min(z_min, z_min * gmax) - margin,
                       std::max(z_max, z_max * gmax) + margin);
    });
    std::map<std::string, FaceFrame> frames;
    for (std::size_t i = 0; i < rec.faces.size(); ++i)
        frames.emplace(rec.faces[i].name, std::move(prepared[i]));
    std::vector<FeatureResult> measured(recipe.features.size());
    core::parallel_for(recipe.features.size(), config.threads, [&](std::size_t i, unsigned) {
        FeatureMeasurer m(recipe, frames, ex, config);
        measured[i] = skeleton(recipe.features[i]);
        m.measure(recipe.features[i], measured[i]);
    });
    for (FeatureResult& r : measured) {
        if (r.hot_mm) {
            r.reason.clear();
            if (out.growth) {
                r.cold_mm = *r.hot_mm / *out.growth;
                r.deviation_mm = *r.cold_mm - r.nominal_mm;
                const bool ok =
                    *r.deviation_mm >= r.tol_lower_mm && *r.deviation_mm <= r.tol_upper_mm;
                r.verdict = ok ? Verdict::kOk : Verdict::kNok;
                if (!ok) r.reason = "deviation outside tolerance";
            } else {
                r.verdict = Verdict::kNotMeasured;
                r.reason = rec.temperature_c
                               ? "part temperature " + std::to_string(*rec.temperature_c) +
                                     " °C outside the plausible range: cold equivalent not "
                                     "available"
                               : "no part temperature in the recording: cold equivalent not "
                                 "available";
            }
        } else {
            r.verdict = Verdict::kNotMeasured;
        }
        out.features.push_back(std::move(r));
    }
    out.verdict = overall(out.features);
    return out;
}

}  // namespace hotgauge::measure
