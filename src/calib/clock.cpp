#include "hotgauge/calib/clock.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>

namespace hotgauge::calib {
namespace {

constexpr double kGateMm = 3.0;      // points within this of a surface (press vibration ≤ 1 mm)
constexpr double kFineGateMm = 0.3;  // ... and of it compensated (6σ of a 0.05 mm sensor)
constexpr int kMinPoints = 20;       // per profile (not measured)
constexpr int kBlocksPerFace = 3;    // for the uncertainty: the offset per block of profiles
constexpr double kStepS = 0.25e-3;   // coarse grid, finer than a quarter period of 47 Hz
constexpr double kFineStepS = 0.05e-3;  // fine grid (not measured)
constexpr double kFineSpanS = 1e-3;     // ... over ± four coarse steps about the coarse best
// A profile's motion counts only along directions its normals weigh at least this fraction
// (M's eigenvalues, which sum to 1): the pseudo-inverse's cut (not measured).
constexpr double kMinNormalWeight = 1e-3;
// The parabolas' span is halved down to this (s): 0.1 µs, far below the 50 µs the clock offset
// is held to (docs/calibration.md) (not measured).
constexpr double kMinSpanS = 1e-7;
// A face takes part with at least this many profiles on the artifact (not measured).
constexpr std::size_t kMinProfiles = 100;
// Below this RMS motion (mm) the head moved too little to time the accelerometer
// (docs/calibration.md: 20 µm; not measured).
constexpr double kMinMotionMm = 0.02;

// One profile's points on the artifact, reduced to what the cost needs: with e_i = d_i + n_i·u,
// Σ e_i² = c + 2·u·b + uᵀ·M·u.
struct ProfileSums {
    std::int64_t k;
    double c = 0.0;
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    int n = 0;
    double motion2 = 0.0;  // |the displacement that fits the points best|², mm² (bᵀ·M⁺·b)
};

struct FaceSums {
    const core::FaceScan* face;
    std::vector<ProfileSums> profiles;
    int points = 0;
};

// `u`: a first estimate of the displacement per profile; points are gated at `gate_mm` from the
// surfaces after moving them by it (the sums stay those of the recorded points).
FaceSums face_sums(const core::FaceScan& f, const Artifact& a,
                   const std::vector<Eigen::Vector3d>* u, double gate_mm) {
    FaceSums out{&f, {}, 0};
    Eigen::Vector3d n;
    for (std::int64_t k = 0; k < f.n_profiles(); ++k) {
        ProfileSums s{k};
        for (std::int64_t i = 0; i < f.width; ++i) {
            if (!std::isfinite(f.x(k, i))) continue;
            const Eigen::Vector3d p = f.nominal_world_point(k, i);
            const Eigen::Vector3d uk = u ? (*u)[k] : Eigen::Vector3d::Zero();
            double best = gate_mm, d = 0.0;
            Eigen::Vector3d nb;
            for (std::size_t j = 0; j < surface_count(a); ++j) {
                const double dj = surface_distance(a, j, p + uk, n);
                if (std::abs(dj) < best) best = std::abs(dj), d = dj - n.dot(uk), nb = n;
            }
            if (best >= gate_mm) continue;
            s.c += d * d;
            s.b += d * nb;
            s.M += nb * nb.transpose();
            ++s.n;
        }
        if (s.n >= kMinPoints) {  // every profile weighs the same: its points share one u
            out.points += s.n;
            s.c /= s.n;
            s.b /= s.n;
            s.M /= s.n;
            const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(s.M);
            for (int e = 0; e < 3; ++e)
                if (eig.eigenvalues()(e) > kMinNormalWeight)
                    s.motion2 +=
                        std::pow(eig.eigenvectors().col(e).dot(s.b), 2) / eig.eigenvalues()(e);
            out.profiles.push_back(s);
        }
    }
    return out;
}

// Σ e² per block (face × kBlocksPerFace) at clock offset `offset_s`, relative to the recording.
std::vector<double> block_costs(const std::vector<FaceSums>& faces,
                                compensate::CompensationConfig config, double offset_s) {
    std::vector<double> cost(faces.size() * kBlocksPerFace, 0.0);
    std::vector<int> counted(cost.size(), 0), all(cost.size(), 0);
    config.clock_offset_s = offset_s;
    config.plate_z = false;  // the offset shows in the integrated u only
    for (std::size_t j = 0; j < faces.size(); ++j) {
        const auto c = compensate::compensate_face(*faces[j].face, config);
        const auto& ps = faces[j].profiles;
        for (std::size_t q = 0; q < ps.size(); ++q) {
            const std::size_t b = j * kBlocksPerFace + q * kBlocksPerFace / ps.size();
            ++all[b];
            const auto k = static_cast<std::size_t>(ps[q].k);
            if (!c.applied || c.profile_degraded[k]) continue;  // not compensated at this offset
            const Eigen::Vector3d& u = c.displacement_mm[k];
            cost[b] += ps[q].c + 2.0 * u.dot(ps[q].b) + u.dot(ps[q].M * u);
            ++counted[b];
        }
    }
    // Per profile counted, scaled to all: an offset that leaves profiles out (near a gap or the
    // record's end) must not look better for it.
    for (std::size_t b = 0; b < cost.size(); ++b)
        cost[b] = counted[b] ? cost[b] / counted[b] * all[b] : 0.0;
    return cost;
}

double total(const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x;
    return s;
}

// Minimum of a parabola through three equally spaced samples, clamped to the span.
double parabola_min(double x, double h, double cm, double c0, double cp) {
    const double curv = cm + cp - 2.0 * c0;
    return curv > 0 ? x + std::clamp(0.5 * h * (cm - cp) / curv, -h, h) : x;
}

struct Search {
    double best = 0.0, cost = 0.0;
    bool at_edge = false;
    std::vector<double> block_min;  // per block of profiles: its own best offset
};

// The offset in [from, to] (s) with the least cost: a grid of `step`, every block's minimum on
// it by a parabola, then successive parabolas on halved spans for all blocks together.
Search search(const std::vector<FaceSums>& faces, const compensate::CompensationConfig& config,
              double from, double to, double step) {
    std::vector<std::vector<double>> grid;
    const int n = static_cast<int>(std::floor((to - from) / step + 1e-9)) + 1;
    for (int g = 0; g < n; ++g) grid.push_back(block_costs(faces, config, from + g * step));
    Search out;
    for (std::size_t b = 0; b < grid.front().size(); ++b) {
        int g0 = 0;
        for (int g = 1; g < n; ++g)
            if (grid[g][b] < grid[g0][b]) g0 = g;
        if (g0 == 0 || g0 == n - 1 || grid[g0][b] == 0.0) continue;
        out.block_min.push_back(
            parabola_min(from + g0 * step, step, grid[g0 - 1][b], grid[g0][b], grid[g0 + 1][b]));
    }
    int g0 = 0;
    for (int g = 1; g < n; ++g)
        if (total(grid[g]) < total(grid[g0])) g0 = g;
    out.at_edge = g0 == 0 || g0 == n - 1;
    out.best = from + g0 * step;
    out.cost = total(grid[g0]);
    for (double h = step; h > kMinSpanS; h *= 0.5) {
        const double cm = total(block_costs(faces, config, out.best - h));
        const double cp = total(block_costs(faces, config, out.best + h));
        const double d = parabola_min(out.best, h, cm, out.cost, cp);
        if (const double c = total(block_costs(faces, config, d)); c < out.cost)
            out.cost = c, out.best = d;
    }
    return out;
}

// Standard uncertainty of the mean of the blocks' offsets.
double scatter_of_mean(const std::vector<double>& x) {
    if (x.size() < 2) return 0.0;
    double m = 0.0, v = 0.0;
    for (double xi : x) m += xi / static_cast<double>(x.size());
    for (double xi : x) v += (xi - m) * (xi - m);
    return std::sqrt(v / static_cast<double>(x.size() - 1) / static_cast<double>(x.size()));
}

std::vector<FaceSums> all_face_sums(const core::Recording& rec, const Artifact& a,
                                    const compensate::CompensationConfig* config, double offset_s,
                                    double gate_mm) {
    std::vector<FaceSums> faces;
    for (const auto& f : rec.faces) {
        std::vector<Eigen::Vector3d> u;
        if (config) {
            compensate::CompensationConfig c = *config;
            c.clock_offset_s = offset_s;
            c.plate_z = false;  // the offset shows in the integrated u only
            u = compensate::compensate_face(f, c).displacement_mm;
            if (u.size() != static_cast<std::size_t>(f.n_profiles())) continue;
        }
        FaceSums s = face_sums(f, a, config ? &u : nullptr, gate_mm);
        if (s.profiles.size() >= kMinProfiles) faces.push_back(std::move(s));
    }
    return faces;
}

}  // namespace

core::Result<ClockOffset> estimate_clock_offset(const core::Recording& rec, const Artifact& a,
                                                const compensate::CompensationConfig& config,
                                                double search_ms) {
    std::vector<FaceSums> faces = all_face_sums(rec, a, nullptr, 0.0, kGateMm);
    if (faces.empty())
        return core::make_error("no face sees the artifact in at least " +
                                std::to_string(kMinProfiles) + " profiles");
    const std::int64_t applied = faces.front().face->clock_offset_ns;
    for (const auto& fs : faces)
        if (fs.face->clock_offset_ns != applied)
            return core::make_error("the faces were recorded with different clock offsets");
    ClockOffset out;
    double still = 0.0, n = 0.0;  // no compensation: how much the head moved
    for (const auto& fs : faces)
        for (const auto& p : fs.profiles) still += p.motion2, n += 1.0;
    out.motion_mm = std::sqrt(still / n);
    if (out.motion_mm < kMinMotionMm)
        return core::make_error("the artifact moved " + std::to_string(out.motion_mm * 1e3) +
                                " µm RMS: too still to time the accelerometer (run the press)");
    // Coarse, on every point near the artifact; then fine, on the points that lie on it once
    // compensated at the coarse offset (reflections and spikes left out).
    const Search coarse = search(faces, config, -search_ms * 1e-3, search_ms * 1e-3, kStepS);
    if (coarse.at_edge)
        return core::make_error("the clock offset is outside the search range of ±" +
                                std::to_string(search_ms) + " ms");
    faces = all_face_sums(rec, a, &config, coarse.best, kFineGateMm);
    if (faces.empty())
        return core::make_error("no face's points fit the artifact once compensated");
    const Search fine =
        search(faces, config, coarse.best - kFineSpanS, coarse.best + kFineSpanS, kFineStepS);
    if (fine.at_edge)
        return core::make_error(
            "the clock offset did not settle: the fine search ended at its edge");
    out.profiles = 0;
    for (const auto& fs : faces) out.profiles += static_cast<int>(fs.profiles.size());
    out.offset_ns = applied + std::llround(fine.best * 1e9);
    out.residual_mm = std::sqrt(fine.cost / out.profiles);
    out.u_ns = scatter_of_mean(fine.block_min) * 1e9;
    return out;
}

}  // namespace hotgauge::calib
