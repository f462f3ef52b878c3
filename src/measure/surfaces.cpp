// Level annuli of the recipe's solid and their fitted planes (docs/measurement.md, "Planes").
#include "surfaces.hpp"

#include <algorithm>
#include <cmath>

#include "hotgauge/measure/fit.hpp"

namespace hotgauge::measure::detail {

double surface_threshold(double rms, const MeasureConfig& c) {
    return std::max(c.on_surface_k_sigma * rms, c.on_surface_min_mm);
}

std::vector<Annulus> annuli_at(const core::AxisymmetricSolid& s, double z) {
    std::vector<Annulus> out;
    std::vector<core::AxisymmetricSolid::Segment> segs;
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

namespace {

// RANSAC on a level (docs/measurement.md, "Planes"): 100 hypotheses, a fixed seed so that a
// recording always measures the same; its consensus band is the on-surface floor, at least 0.1 mm.
constexpr int kRansacIterations = 100;
constexpr std::uint64_t kRansacSeed = 7;
constexpr double kMinRansacThresholdMm = 0.1;
constexpr int kRejectRounds = 10;  // of the robust plane fits (fit.hpp's default)

// Samples with their profile keys (face index << 32 | profile).
struct KeyedPoints {
    std::vector<Eigen::Vector3d> points;
    std::vector<std::int64_t> keys;
};

// The samples of all faces within band of z_e and between r_lo and r_hi about the axis, `found`
// of them. A plane is known to a fraction of a micrometre from tens of thousands of points: of
// more than `max_points`, an even subsample (every k-th in face and bucket order) keeps the fit's
// cost bounded; they are counted first, so that only the kept ones are copied.
KeyedPoints level_candidates(const std::vector<const FaceFrame*>& frames, double z_e, double band,
                             double r_lo, double r_hi, std::size_t max_points, std::size_t& found) {
    auto on_level = [&](const FaceFrame::Near& s) {
        return std::abs(s.p.z() - z_e) <= band && s.r >= r_lo && s.r <= r_hi;
    };
    found = 0;
    for (const FaceFrame* f : frames)
        f->for_z(z_e - band, z_e + band, [&](const FaceFrame::Near& s) { found += on_level(s); });
    const std::size_t keep_every = found <= max_points ? 1 : (found + max_points - 1) / max_points;
    KeyedPoints out;
    out.points.reserve(found / keep_every + 1);
    out.keys.reserve(found / keep_every + 1);
    std::size_t seen = 0;
    for (std::size_t fi = 0; fi < frames.size(); ++fi)
        frames[fi]->for_z(z_e - band, z_e + band, [&](const FaceFrame::Near& s) {
            if (!on_level(s) || seen++ % keep_every != 0) return;
            out.points.push_back(s.p.cast<double>());
            out.keys.push_back(static_cast<std::int64_t>(fi) << 32 | s.q / frames[fi]->w);
        });
    return out;
}

// RANSAC scores hypotheses on an even subsample (a few thousand points decide a plane as well as
// a few hundred thousand); all candidates are then classified against its plane: those within
// `thr` of it.
core::Result<KeyedPoints> ransac_consensus(const KeyedPoints& cand, double thr) {
    constexpr std::size_t kRansacPoints = 4000;
    std::vector<Eigen::Vector3d> sub;
    const std::size_t stride = std::max<std::size_t>(1, cand.points.size() / kRansacPoints);
    for (std::size_t q = 0; q < cand.points.size(); q += stride) sub.push_back(cand.points[q]);
    auto seed = ransac_plane(sub, {thr, kRansacIterations, kRansacSeed});
    if (!seed) return seed.error();
    KeyedPoints in;
    for (std::size_t q = 0; q < cand.points.size(); ++q)
        if (std::abs(seed->fit.distance(cand.points[q])) <= thr) {
            in.points.push_back(cand.points[q]);
            in.keys.push_back(cand.keys[q]);
        }
    return in;
}

}  // namespace

PlaneResult fit_level_plane(const std::vector<const FaceFrame*>& frames, double z_e, double band,
                            double r_lo, double r_hi, const MeasureConfig& c,
                            const std::string& what) {
    constexpr std::size_t kMaxPlanePoints = 20000;  // level_candidates: why
    PlaneResult out;
    std::size_t found = 0;
    KeyedPoints cand = level_candidates(frames, z_e, band, r_lo, r_hi, kMaxPlanePoints, found);
    if (found < static_cast<std::size_t>(std::max(c.min_plane_points, 0))) {
        out.error = what + ": only " + std::to_string(found) + " points where the plane should be";
        return out;
    }
    const auto in = ransac_consensus(cand, std::max(c.on_surface_min_mm, kMinRansacThresholdMm));
    if (!in) {
        out.error = what + ": " + in.error().message;
        return out;
    }
    auto fit = fit_plane_robust(in->points, {c.on_surface_k_sigma, 0.0, kRejectRounds});
    if (!fit) {
        out.error = what + ": " + fit.error().message;
        return out;
    }
    for (std::size_t q = 0; q < in->points.size(); ++q)
        if (fit->inlier[q]) {
            out.points.push_back(in->points[q]);
            out.profile_keys.push_back(in->keys[q]);
        }
    out.fit = fit->fit;
    return out;
}

double profile_scatter(const PlaneResult& pl) {
    const std::vector<Eigen::Vector3d>& points = pl.points;
    const std::vector<std::int64_t>& key = pl.profile_keys;
    const PlaneFit& plane = pl.fit;
    constexpr std::size_t kMinPointsPerProfile = 20;
    // With fewer profiles than this the scatter is taken as 0 (not measured).
    constexpr int kMinProfiles = 10;
    std::vector<std::size_t> order(points.size());
    for (std::size_t q = 0; q < order.size(); ++q) order[q] = q;
    std::sort(order.begin(), order.end(), [&](auto a, auto b) { return key[a] < key[b]; });
    double s_mean2 = 0, s_noise2 = 0;
    std::size_t profiles = 0;
    for (std::size_t a = 0; a < order.size();) {
        std::size_t b = a;
        double s = 0, s2 = 0;
        for (; b < order.size() && key[order[b]] == key[order[a]]; ++b) {
            const double d = plane.distance(points[order[b]]);
            s += d;
            s2 += d * d;
        }
        const auto n = static_cast<double>(b - a);
        if (b - a >= kMinPointsPerProfile) {
            const double mean = s / n, var = std::max(0.0, s2 / n - mean * mean);
            s_mean2 += mean * mean;
            s_noise2 += var / (n - 1.0);
            ++profiles;
        }
        a = b;
    }
    if (profiles < kMinProfiles) return 0.0;
    return std::sqrt(std::max(0.0, (s_mean2 - s_noise2) / static_cast<double>(profiles)));
}

namespace {

// Residuals against the radius about the axis, d = a + b·x + c·x² (x from the mean radius): a
// cone (b) or a bend (c) across the face beyond 4σ and 4 µm over its width is no flat face, but
// fillets meeting on a face narrower than they are (the bore step, 0.3 mm flat).
bool curved_across(const PlaneResult& pl) {
    // 4 µm and 4σ, as the bins' kMinOffMm and kOffSigma below.
    constexpr double kMinSagMm = 0.004, kSagSigma = 4.0;
    const auto n = static_cast<double>(pl.points.size());
    double r_mean = 0;
    for (const auto& p : pl.points) r_mean += p.head<2>().norm() / n;
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    double half = 0;
    for (const auto& p : pl.points) {
        const double x = p.head<2>().norm() - r_mean;
        const Eigen::Vector3d row(1.0, x, x * x);
        A += row * row.transpose();
        b += row * pl.fit.distance(p);
        half = std::max(half, std::abs(x));
    }
    const Eigen::Matrix3d cov = A.inverse() * pl.fit.rms_mm * pl.fit.rms_mm;
    const Eigen::Vector3d k = A.ldlt().solve(b);
    const bool cone =
        std::abs(k[1]) > kSagSigma * std::sqrt(cov(1, 1)) && std::abs(k[1]) * half > kMinSagMm;
    const bool bend = std::abs(k[2]) > kSagSigma * std::sqrt(cov(2, 2)) &&
                      std::abs(k[2]) * half * half > kMinSagMm;
    return cone || bend;
}

// The bins of keep_flat_part: 0.25 mm wide; one with fewer than 20 samples is too sparse to
// judge, and one sits off the plane when its mean is beyond 4σ of it and 4 µm.
constexpr double kBinMm = 0.25, kMinOffMm = 0.004, kOffSigma = 4.0;
constexpr std::size_t kMinBin = 20;

// A plane's inliers in radial bins of kBinMm about the axis, from the innermost one: the sum and
// count of their distances from the plane.
struct RadialBins {
    double r_lo = 1e300, r_hi = -1e300;
    std::size_t nb = 0;
    std::vector<double> sum;
    std::vector<std::size_t> cnt;
    std::size_t of(const Eigen::Vector3d& p) const {
        return std::min(nb - 1, static_cast<std::size_t>((p.head<2>().norm() - r_lo) / kBinMm));
    }
    // How far bin b sits off the plane beyond its noise, or 0 (within it, or too few to tell).
    double off(std::size_t b, double rms_mm) const {
        if (cnt[b] < kMinBin) return 0.0;  // too few to tell
        const double mean = sum[b] / static_cast<double>(cnt[b]);
        const double limit =
            std::max(kMinOffMm, kOffSigma * rms_mm / std::sqrt(static_cast<double>(cnt[b])));
        return std::abs(mean) > limit ? std::abs(mean) : 0.0;
    }
};

RadialBins radial_bins(const PlaneResult& pl) {
    RadialBins bins;
    for (const auto& p : pl.points) {
        bins.r_lo = std::min(bins.r_lo, p.head<2>().norm());
        bins.r_hi = std::max(bins.r_hi, p.head<2>().norm());
    }
    bins.nb = static_cast<std::size_t>((bins.r_hi - bins.r_lo) / kBinMm) + 1;
    bins.sum.assign(bins.nb, 0.0);
    bins.cnt.assign(bins.nb, 0);
    for (const auto& p : pl.points) {
        bins.sum[bins.of(p)] += pl.fit.distance(p);
        bins.cnt[bins.of(p)]++;
    }
    return bins;
}

// Why a narrow face's bins cannot tell its flat part from its fillets, or empty.
std::string narrow_unjudgeable(const RadialBins& bins, const PlaneResult& pl,
                               const std::string& what) {
    // Seen across less than a bin: nothing tells its flat part from its fillets (a 0.1 mm band of
    // the bore step's fillet, 64 samples, looked flat and read Height 1 0.12 mm small with u
    // 0.02 mm), so no plane.
    if (bins.nb < 2)
        return what + ": " + std::to_string(bins.r_hi - bins.r_lo) +
               " mm of the face seen, narrower than the " + std::to_string(kBinMm) +
               " mm that tell its flat part from its fillets";
    // Edge bins too sparse to judge: its fillet tails cannot be told from its flat part (the bore
    // step seen through a 39 mm deep bore: 109 samples, 0.05 mm off), so no plane.
    if (bins.cnt[0] < kMinBin || bins.cnt[bins.nb - 1] < kMinBin)
        return what + ": too few samples (" + std::to_string(pl.points.size()) +
               ") to tell its flat part from its fillets";
    return {};
}

std::string no_flat_part(const RadialBins& bins, const std::string& what) {
    return what + ": no flat part between its fillets (" + std::to_string(bins.r_hi - bins.r_lo) +
           " mm of the face seen, curved across)";
}

// The plane fitted again without bin `drop`; false (and pl.error) when too few points are left
// or the face has fewer than three bins: no flat part.
bool refit_without_bin(PlaneResult& pl, const RadialBins& bins, std::size_t drop,
                       const MeasureConfig& c, const std::string& what) {
    PlaneResult kept;
    for (std::size_t q = 0; q < pl.points.size(); ++q)
        if (bins.of(pl.points[q]) != drop) {
            kept.points.push_back(pl.points[q]);
            kept.profile_keys.push_back(pl.profile_keys[q]);
        }
    auto fit = kept.points.size() >= static_cast<std::size_t>(c.min_plane_points)
                   ? fit_plane_robust(kept.points, {c.on_surface_k_sigma, 0.0, kRejectRounds})
                   : core::Result<RobustPlaneFit>(core::make_error("too few points"));
    if (!fit || bins.nb < 3) {
        pl.error = no_flat_part(bins, what);
        return false;
    }
    pl.fit = fit->fit;
    pl.points = std::move(kept.points);
    pl.profile_keys = std::move(kept.profile_keys);
    return true;
}

// The plane on the level's flat part only (forged parts): the inliers in radial bins of 0.25 mm
// about the axis; while the innermost or outermost bin sits off the plane by more than its noise
// allows (a fillet's tail running into the annulus), it is dropped and the plane fitted again.
void keep_flat_part(PlaneResult& pl, bool narrow, const MeasureConfig& c, const std::string& what) {
    constexpr int kMaxRounds = 40;
    for (int round = 0; round < kMaxRounds; ++round) {
        const RadialBins bins = radial_bins(pl);
        if (narrow) {
            std::string why = narrow_unjudgeable(bins, pl, what);
            if (!why.empty()) {
                pl.error = std::move(why);
                return;
            }
        }
        const double lo = bins.off(0, pl.fit.rms_mm), hi = bins.off(bins.nb - 1, pl.fit.rms_mm);
        if (lo == 0.0 && hi == 0.0) {
            if (narrow && curved_across(pl)) pl.error = no_flat_part(bins, what);
            return;
        }
        if (!refit_without_bin(pl, bins, lo >= hi ? 0 : bins.nb - 1, c, what)) return;
    }
}

}  // namespace

bool Context::faces_sensors(const Annulus& a, const std::vector<const FaceFrame*>& frames) {
    // A face seen at less than about 6° is edge-on (a horizontal side sensor and the flange
    // underside, tilted by a matched pose's few µrad), not seen.
    constexpr double kMinViewZ = 0.1;
    for (const auto* fr : frames)
        if (a.facing * fr->view.z() > -kMinViewZ) return false;
    return true;
}

std::optional<Annulus> Context::annulus(const std::string& level, double R,
                                        const std::vector<const FaceFrame*>& frames,
                                        std::string& why) const {
    for (const auto& a : annuli_at(solid, level_z(level))) {
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

PlaneResult Context::level_plane(const std::string& level, const Annulus& a,
                                 const std::vector<const FaceFrame*>& frames) const {
    PlaneMemo::Key key{level, a.lo, a.hi, a.facing, frames};
    {
        std::lock_guard lock(memo->mutex);
        if (auto it = memo->planes.find(key); it != memo->planes.end()) return it->second;
    }
    PlaneResult pl = fit_annulus_plane(level, a, frames);
    std::lock_guard lock(memo->mutex);
    return memo->planes.emplace(std::move(key), std::move(pl)).first->second;
}

PlaneResult Context::fit_annulus_plane(const std::string& level, const Annulus& a,
                                       const std::vector<const FaceFrame*>& frames) const {
    const double z = level_z(level);
    // A face narrower than its two largest fillets and a millimetre has no flat part by drawing.
    const bool narrow = (a.hi - a.lo) < 2.0 * recipe.fillet_at(level) + 1.0;
    // A wider one's fillets are left out by drawing: its flat part starts at most the drawing's
    // largest fillet (and the dimensions' scatter) from each corner. Their tails, each within the
    // bins' noise of the plane, had pulled the boss top 13 µm towards the material on a forged
    // part (Height 4 read 0.0075 mm small on the mean), and its recess corner with it.
    constexpr double kScatterMm = 0.25;
    const double m = recipe.forging && !narrow
                         ? std::max(c.support_margin_mm, recipe.fillet_at(level) + kScatterMm)
                         : c.support_margin_mm;
    PlaneResult pl =
        fit_level_plane(frames, ex.z(z), ex.tol(c.plane_band_mm, z), ex.z(a.lo) + ex.tol(m, a.lo),
                        ex.z(a.hi) - ex.tol(m, a.hi), c, "plane at level '" + level + "'");
    if (pl.error.empty() && recipe.forging)
        keep_flat_part(pl, narrow, c, "plane at level '" + level + "'");
    if (pl.error.empty()) {
        const double tilt = std::acos(std::min(1.0, std::abs(pl.fit.normal.z()))) * kRadToDeg;
        // On a narrow forged face a steep plane is its fillets and walls: no flat part.
        if (tilt > c.max_plane_tilt_deg)
            pl.error = narrow && recipe.forging
                           ? "plane at level '" + level + "': no flat part between its fillets (" +
                                 "what is seen there fits a surface tilted " +
                                 std::to_string(tilt) + "° from the part axis)"
                           : "plane at level '" + level + "' is tilted " + std::to_string(tilt) +
                                 "° from the part axis: wrong pose or wrong part";
    }
    return pl;
}

}  // namespace hotgauge::measure::detail
