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

PlaneResult fit_level_plane(const std::vector<const FaceFrame*>& frames, double z_e, double band,
                            double r_lo, double r_hi, const MeasureConfig& c,
                            const std::string& what) {
    PlaneResult out;
    std::vector<Eigen::Vector3d> cand;
    std::vector<std::int64_t> key;  // face index << 32 | profile
    for (std::size_t fi = 0; fi < frames.size(); ++fi)
        frames[fi]->for_z(z_e - band, z_e + band, [&](const FaceFrame::Near& s) {
            if (std::abs(s.p.z() - z_e) <= band && s.r >= r_lo && s.r <= r_hi) {
                cand.push_back(s.p.cast<double>());
                key.push_back(static_cast<std::int64_t>(fi) << 32 | s.q / frames[fi]->w);
            }
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
        for (std::size_t q = 0; q < cand.size(); q += keep_every, ++m) {
            cand[m] = cand[q];
            key[m] = key[q];
        }
        cand.resize(m);
        key.resize(m);
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
    std::vector<std::int64_t> in_key;
    for (std::size_t q = 0; q < cand.size(); ++q)
        if (std::abs(seed->fit.distance(cand[q])) <= ransac_thr) {
            in.push_back(cand[q]);
            in_key.push_back(key[q]);
        }
    auto fit = fit_plane_robust(in, {c.on_surface_k_sigma, 0.0, 10});
    if (!fit) {
        out.error = what + ": " + fit.error().message;
        return out;
    }
    for (std::size_t q = 0; q < in.size(); ++q)
        if (fit->inlier[q]) {
            out.points.push_back(in[q]);
            out.profile_keys.push_back(in_key[q]);
        }
    out.fit = fit->fit;
    return out;
}

double profile_scatter(const PlaneResult& pl) {
    const std::vector<Eigen::Vector3d>& points = pl.points;
    const std::vector<std::int64_t>& key = pl.profile_keys;
    const PlaneFit& plane = pl.fit;
    constexpr std::size_t kMinPointsPerProfile = 20;
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
    if (profiles < 10) return 0.0;
    return std::sqrt(std::max(0.0, (s_mean2 - s_noise2) / static_cast<double>(profiles)));
}

namespace {

// Residuals against the radius about the axis, d = a + b·x + c·x² (x from the mean radius): a
// cone (b) or a bend (c) across the face beyond 4σ and 4 µm over its width is no flat face, but
// fillets meeting on a face narrower than they are (the bore step, 0.3 mm flat).
bool curved_across(const PlaneResult& pl) {
    constexpr double kMinSagMm = 0.004;
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
        std::abs(k[1]) > 4.0 * std::sqrt(cov(1, 1)) && std::abs(k[1]) * half > kMinSagMm;
    const bool bend =
        std::abs(k[2]) > 4.0 * std::sqrt(cov(2, 2)) && std::abs(k[2]) * half * half > kMinSagMm;
    return cone || bend;
}

// The plane on the level's flat part only (forged parts): the inliers in radial bins of 0.25 mm
// about the axis; while the innermost or outermost bin sits off the plane by more than its noise
// allows (a fillet's tail running into the annulus), it is dropped and the plane fitted again.
void keep_flat_part(PlaneResult& pl, bool narrow, const MeasureConfig& c, const std::string& what) {
    constexpr double kBinMm = 0.25, kMinOffMm = 0.004;
    constexpr std::size_t kMinBin = 20;
    for (int round = 0; round < 40; ++round) {
        double r_lo = 1e300, r_hi = -1e300;
        for (const auto& p : pl.points) {
            r_lo = std::min(r_lo, p.head<2>().norm());
            r_hi = std::max(r_hi, p.head<2>().norm());
        }
        const auto nb = static_cast<std::size_t>((r_hi - r_lo) / kBinMm) + 1;
        std::vector<double> sum(nb, 0.0);
        std::vector<std::size_t> cnt(nb, 0);
        auto bin = [&](const Eigen::Vector3d& p) {
            return std::min(nb - 1, static_cast<std::size_t>((p.head<2>().norm() - r_lo) / kBinMm));
        };
        for (const auto& p : pl.points) {
            sum[bin(p)] += pl.fit.distance(p);
            cnt[bin(p)]++;
        }
        // A narrow face seen across less than a bin: nothing tells its flat part from its
        // fillets (a 0.1 mm band of the bore step's fillet, 64 samples, looked flat and read
        // Height 1 0.12 mm small with u 0.02 mm), so no plane.
        if (narrow && nb < 2) {
            pl.error = what + ": " + std::to_string(r_hi - r_lo) +
                       " mm of the face seen, narrower than the " + std::to_string(kBinMm) +
                       " mm that tell its flat part from its fillets";
            return;
        }
        // A narrow face whose edge bins are too sparse to judge: its fillet tails cannot be
        // told from its flat part (the bore step seen through a 39 mm deep bore: 109 samples,
        // 0.05 mm off), so no plane.
        if (narrow && (cnt[0] < kMinBin || cnt[nb - 1] < kMinBin)) {
            pl.error = what + ": too few samples (" + std::to_string(pl.points.size()) +
                       ") to tell its flat part from its fillets";
            return;
        }
        auto off = [&](std::size_t b) {
            if (cnt[b] < kMinBin) return 0.0;  // too few to tell
            const double mean = sum[b] / static_cast<double>(cnt[b]);
            const double limit =
                std::max(kMinOffMm, 4.0 * pl.fit.rms_mm / std::sqrt(static_cast<double>(cnt[b])));
            return std::abs(mean) > limit ? std::abs(mean) : 0.0;
        };
        const double lo = off(0), hi = off(nb - 1);
        if (lo == 0.0 && hi == 0.0) {
            if (narrow && curved_across(pl))
                pl.error = what + ": no flat part between its fillets (" +
                           std::to_string(r_hi - r_lo) + " mm of the face seen, curved across)";
            return;
        }
        const std::size_t drop = lo >= hi ? 0 : nb - 1;
        PlaneResult kept;
        for (std::size_t q = 0; q < pl.points.size(); ++q)
            if (bin(pl.points[q]) != drop) {
                kept.points.push_back(pl.points[q]);
                kept.profile_keys.push_back(pl.profile_keys[q]);
            }
        auto fit = kept.points.size() >= static_cast<std::size_t>(c.min_plane_points)
                       ? fit_plane_robust(kept.points, {c.on_surface_k_sigma, 0.0, 10})
                       : core::Result<RobustPlaneFit>(core::make_error("too few points"));
        if (!fit || nb < 3) {
            pl.error = what + ": no flat part between its fillets (" + std::to_string(r_hi - r_lo) +
                       " mm of the face seen, curved across)";
            return;
        }
        pl.fit = fit->fit;
        pl.points = std::move(kept.points);
        pl.profile_keys = std::move(kept.profile_keys);
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
