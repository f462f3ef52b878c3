// Scene preparation from the organised scans: the (profile, column) grid gives neighbours for
// free, so there is no 3-D voxel grid over millions of points (algorithm-notes: the open
// libraries spend most of their preparation there).
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <random>
#include <unordered_map>

#include "internal.hpp"

namespace hotgauge::match::detail {
namespace {

// A face's column pitch is the median over every n/16-th profile, and either pitch is floored at
// 1 µm; a face with nothing to measure takes 1 mm (not measured).
constexpr std::int64_t kPitchProfileShare = 16;
constexpr double kMinPitchMm = 1e-3, kFallbackPitchMm = 1.0;
// A voting sample's normal: neighbours farther than this many normal radii are across a depth
// jump; at least this many of the 3 × 3 must remain, and the smallest eigenvalue be at most this
// share of their spread's (else an edge or a spike, not a smooth surface) (not measured).
constexpr double kMaxJumpRadii = 3.0;
constexpr int kMinNeighbours = 6;
constexpr float kMaxFlatness = 0.05f;
// The background plane: RANSAC hypotheses from a fixed seed (the same scan, the same plane), and
// at least this many samples to look for one in and to accept one (not measured).
constexpr int kPlaneHypotheses = 200, kPlaneSeed = 12345, kMinPlaneSamples = 50;

// World-point access to one face, compensated when u is given.
class FaceGrid {
  public:
    FaceGrid(const core::FaceScan& f, const std::vector<Eigen::Vector3d>* u) : f_(f), u_(u) {
        if (u_ && u_->size() != static_cast<std::size_t>(f.n_profiles())) u_ = nullptr;
        R_ = f.T_world_camera.linear().cast<float>();
        t_ = f.T_world_camera.translation().cast<float>();
        dir_ = f.scan_direction.cast<float>();
        col_pitch_ = median_column_pitch();
        prof_pitch_ = median_profile_pitch();
    }
    std::int64_t n() const { return f_.n_profiles(); }
    std::int64_t w() const { return f_.width; }
    bool valid(std::int64_t k, std::int64_t i) const {
        return !std::isnan(f_.x(k, i)) && !std::isnan(f_.z(k, i));
    }
    Eigen::Vector3f point(std::int64_t k, std::int64_t i) const {
        return R_ * Eigen::Vector3f(f_.x(k, i), 0.0f, f_.z(k, i)) + origin(k);
    }
    // Camera origin at profile k (the sensor the surface was seen from).
    Eigen::Vector3f origin(std::int64_t k) const {
        Eigen::Vector3f o = t_ + static_cast<float>(f_.profile_positions_mm[k]) * dir_;
        if (u_) o += (*u_)[k].cast<float>();
        return o;
    }
    // Grid strides for a pitch of about `mm` in the world.
    std::int64_t column_stride(double mm) const {
        return std::max<std::int64_t>(1, std::llround(mm / col_pitch_));
    }
    std::int64_t profile_stride(double mm) const {
        return std::max<std::int64_t>(1, std::llround(mm / prof_pitch_));
    }

  private:
    double median_column_pitch() const {
        std::vector<double> d;
        const std::int64_t step = std::max<std::int64_t>(1, n() / kPitchProfileShare);
        for (std::int64_t k = 0; k < n(); k += step)
            for (std::int64_t i = 0; i + 1 < w(); ++i)
                if (valid(k, i) && valid(k, i + 1))
                    d.push_back(std::abs(f_.x(k, i + 1) - f_.x(k, i)));
        if (d.empty()) return kFallbackPitchMm;
        std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
        return std::max(kMinPitchMm, d[d.size() / 2]);
    }
    double median_profile_pitch() const {
        std::vector<double> d;
        for (std::int64_t k = 0; k + 1 < n(); ++k)
            d.push_back(std::abs(f_.profile_positions_mm[k + 1] - f_.profile_positions_mm[k]));
        if (d.empty()) return kFallbackPitchMm;
        std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
        return std::max(kMinPitchMm, d[d.size() / 2]);
    }

    const core::FaceScan& f_;
    const std::vector<Eigen::Vector3d>* u_;
    Eigen::Matrix3f R_;
    Eigen::Vector3f t_, dir_;
    double col_pitch_ = 1, prof_pitch_ = 1;
};

const std::vector<Eigen::Vector3d>* face_u(const core::FaceDisplacements& u,
                                           const std::string& name) {
    auto it = u.find(name);
    return it == u.end() ? nullptr : &it->second;
}

inline std::int64_t voxel_key(const Eigen::Vector3f& p, float inv) {
    const auto c = (p * inv).array().floor().cast<std::int64_t>();
    return (c.x() * 73856093) ^ (c.y() * 19349663) ^ (c.z() * 83492791);
}

}  // namespace

Samples voting_samples(const core::Recording& rec, const core::FaceDisplacements& u,
                       double sampling_mm, double normal_radius_mm) {
    Samples out;
    std::unordered_map<std::int64_t, std::uint32_t> taken;
    const float inv = static_cast<float>(1.0 / sampling_mm);
    const float max_jump = static_cast<float>(kMaxJumpRadii * normal_radius_mm);
    for (const auto& face : rec.faces) {
        if (face.width < 3 || face.n_profiles() < 3) continue;
        const FaceGrid g(face, face_u(u, face.name));
        const std::int64_t si = g.column_stride(0.5 * sampling_mm);
        const std::int64_t sk = g.profile_stride(0.5 * sampling_mm);
        const std::int64_t hi = g.column_stride(normal_radius_mm);
        const std::int64_t hk = g.profile_stride(normal_radius_mm);
        for (std::int64_t k = hk; k + hk < g.n(); k += sk)
            for (std::int64_t i = hi; i + hi < g.w(); i += si) {
                if (!g.valid(k, i)) continue;
                const Eigen::Vector3f c = g.point(k, i);
                const std::int64_t vk = voxel_key(c, inv);
                if (taken.count(vk)) continue;
                // PCA of the 3 × 3 grid neighbourhood at the normal radius; neighbours across a
                // depth jump (another surface) are left out.
                Eigen::Vector3f nb[9];
                int m = 0;
                for (int a = -1; a <= 1; ++a)
                    for (int b = -1; b <= 1; ++b) {
                        const std::int64_t kk = k + a * hk, ii = i + b * hi;
                        if (!g.valid(kk, ii)) continue;
                        const Eigen::Vector3f p = g.point(kk, ii);
                        if ((p - c).norm() < max_jump) nb[m++] = p;
                    }
                if (m < kMinNeighbours) continue;
                Eigen::Vector3f mean = Eigen::Vector3f::Zero();
                for (int q = 0; q < m; ++q) mean += nb[q];
                mean /= static_cast<float>(m);
                Eigen::Matrix3f C = Eigen::Matrix3f::Zero();
                for (int q = 0; q < m; ++q) C += (nb[q] - mean) * (nb[q] - mean).transpose();
                Eigen::SelfAdjointEigenSolver<Eigen::Matrix3f> es;
                es.computeDirect(C);
                const Eigen::Vector3f ev = es.eigenvalues();
                // Not a smooth surface: an edge, a spike.
                if (ev(0) > kMaxFlatness * ev.sum()) continue;
                Eigen::Vector3f n = es.eigenvectors().col(0);
                if (n.dot(g.origin(k) - c) < 0) n = -n;
                taken.emplace(vk, static_cast<std::uint32_t>(out.points.size()));
                out.points.push_back(c);
                out.normals.push_back(n);
            }
    }
    return out;
}

std::vector<Eigen::Vector3f> grid_points(const core::Recording& rec,
                                         const core::FaceDisplacements& u, double grid_mm) {
    std::vector<Eigen::Vector3f> out;
    for (const auto& face : rec.faces) {
        if (face.width < 1 || face.n_profiles() < 1) continue;
        const FaceGrid g(face, face_u(u, face.name));
        const std::int64_t si = g.column_stride(grid_mm), sk = g.profile_stride(grid_mm);
        for (std::int64_t k = 0; k < g.n(); k += sk)
            for (std::int64_t i = 0; i < g.w(); i += si)
                if (g.valid(k, i)) out.push_back(g.point(k, i));
    }
    return out;
}

std::optional<Plane> background_plane(const Samples& s, double band_mm, double min_extent_mm) {
    const std::size_t n = s.points.size();
    if (n < kMinPlaneSamples) return std::nullopt;
    std::mt19937 rng(kPlaneSeed);
    std::uniform_int_distribution<std::size_t> pick(0, n - 1);
    const float band = static_cast<float>(band_mm);
    constexpr float kCosNormal = 0.94f;  // 20°
    auto count = [&](const Plane& pl) {
        std::size_t c = 0;
        for (std::size_t i = 0; i < n; ++i)
            c += std::abs(pl.distance(s.points[i])) < band &&
                 std::abs(pl.n.dot(s.normals[i])) > kCosNormal;
        return c;
    };
    std::optional<Plane> best;
    std::size_t best_count = 0;
    for (int it = 0; it < kPlaneHypotheses; ++it) {
        // One oriented sample defines a plane; a second must agree with it.
        const std::size_t a = pick(rng), b = pick(rng);
        const Plane pl{s.normals[a], s.normals[a].dot(s.points[a])};
        if (std::abs(pl.distance(s.points[b])) > band ||
            std::abs(pl.n.dot(s.normals[b])) < kCosNormal)
            continue;
        const std::size_t c = count(pl);
        if (c > best_count) {
            best_count = c;
            best = pl;
        }
    }
    if (!best || best_count < kMinPlaneSamples) return std::nullopt;
    // Least-squares refit on the inliers, then the extent test.
    std::vector<Eigen::Vector3f> in;
    for (std::size_t i = 0; i < n; ++i)
        if (std::abs(best->distance(s.points[i])) < band &&
            std::abs(best->n.dot(s.normals[i])) > kCosNormal)
            in.push_back(s.points[i]);
    Eigen::Vector3f mean = Eigen::Vector3f::Zero();
    for (const auto& p : in) mean += p;
    mean /= static_cast<float>(in.size());
    Eigen::Matrix3f C = Eigen::Matrix3f::Zero();
    for (const auto& p : in) C += (p - mean) * (p - mean).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3f> es;
    es.computeDirect(C);
    Eigen::Vector3f nrm = es.eigenvectors().col(0);
    if (nrm.dot(best->n) < 0) nrm = -nrm;
    const Plane fit{nrm, nrm.dot(mean)};
    // Extent: the two largest principal spreads of the inliers (≈ ±√3σ for a uniform patch).
    const float extent =
        2.0f * std::sqrt(3.0f * es.eigenvalues()(2) / static_cast<float>(in.size()));
    if (extent < static_cast<float>(min_extent_mm)) return std::nullopt;
    return fit;
}

}  // namespace hotgauge::match::detail
