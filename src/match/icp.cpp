// Robust point-to-plane ICP against the model surface (docs/matching.md). Axisymmetric models use
// the exact (r, z) profile: the closest point is found in the meridian half-plane, with no
// sampling error and no tree; other models use a FLANN k-d tree over their dense samples.
#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <flann/flann.hpp>
#include <optional>

#include "internal.hpp"

namespace hotgauge::match::detail {
namespace {

// The k-d tree's leaf size, as estimate_normals' (not measured).
constexpr int kKdLeafSize = 15;
// The dense samples' spacing: the median nearest-neighbour distance over about this many of them
// (not measured).
constexpr int kSpacingSamples = 500;

}  // namespace

struct Surface::KdTree {
    flann::Matrix<float> data;
    flann::Index<flann::L2_Simple<float>> index;
    explicit KdTree(const std::vector<Eigen::Vector3f>& pts)
        : data(const_cast<float*>(pts.front().data()), pts.size(), 3, sizeof(Eigen::Vector3f)),
          index(data, flann::KDTreeSingleIndexParams(kKdLeafSize)) {
        index.buildIndex();
    }
};

Surface::Surface(const Model& model) : model_(model) {
    lo_ = Eigen::Vector3f::Constant(std::numeric_limits<float>::max());
    hi_ = -lo_;
    if (model.axisymmetric) {
        for (const auto& s : model.profile) {
            hi_.x() = std::max({hi_.x(), static_cast<float>(s.r0), static_cast<float>(s.r1)});
            lo_.z() = std::min({lo_.z(), static_cast<float>(s.z0), static_cast<float>(s.z1)});
            hi_.z() = std::max({hi_.z(), static_cast<float>(s.z0), static_cast<float>(s.z1)});
        }
        hi_.y() = hi_.x();
        lo_.x() = lo_.y() = -hi_.x();
        build_profile_grid();
    } else {
        for (const auto& p : model.dense_points) {
            lo_ = lo_.cwiseMin(p);
            hi_ = hi_.cwiseMax(p);
        }
        if (!model.dense_points.empty()) {
            tree_ = new KdTree(model.dense_points);
            // Sample spacing: the median nearest-neighbour distance of a subset.
            std::vector<float> nn;
            const std::size_t step =
                std::max<std::size_t>(1, model.dense_points.size() / kSpacingSamples);
            for (std::size_t i = 0; i < model.dense_points.size(); i += step) {
                int idx[2];
                float d2[2];
                flann::Matrix<float> query(const_cast<float*>(model.dense_points[i].data()), 1, 3);
                flann::Matrix<int> indices(idx, 1, 2);
                flann::Matrix<float> dists(d2, 1, 2);
                tree_->index.knnSearch(query, indices, dists, 2, flann::SearchParams(-1));
                nn.push_back(std::sqrt(d2[1]));
            }
            std::nth_element(nn.begin(), nn.begin() + nn.size() / 2, nn.end());
            dense_spacing_ = nn[nn.size() / 2];
        }
    }
    half_size_ = 0.5f * (hi_ - lo_).norm();
}

float Surface::Seg::distance2(float r, float z, float& t) const {
    t = std::clamp((r - r0) * ur + (z - z0) * uz, 0.0f, len);
    const float dr = r0 + t * ur - r, dz = z0 + t * uz - z;
    return dr * dr + dz * dz;
}

void Surface::build_profile_grid() {
    for (const auto& s : model_.profile) {
        const double dr = s.r1 - s.r0, dz = s.z1 - s.z0, len = s.length();
        segs_.push_back({static_cast<float>(s.r0), static_cast<float>(s.z0),
                         static_cast<float>(dr / len), static_cast<float>(dz / len),
                         static_cast<float>(len), static_cast<float>(dz / len),
                         static_cast<float>(-dr / len)});
    }
    constexpr float kMargin = 30.0f;
    r0_ = 0.0f;
    z0_ = lo_.z() - kMargin;
    nr_ = static_cast<int>(std::ceil((hi_.x() + kMargin) / cell_mm_));
    nz_ = static_cast<int>(std::ceil((hi_.z() - lo_.z() + 2 * kMargin) / cell_mm_));
    cell_begin_.assign(static_cast<std::size_t>(nr_ * nz_) + 1, 0);
    std::vector<float> dmin(segs_.size());
    for (int a = 0; a < nr_; ++a)
        for (int b = 0; b < nz_; ++b) {
            const float r_lo = r0_ + static_cast<float>(a) * cell_mm_, r_hi = r_lo + cell_mm_;
            const float z_lo = z0_ + static_cast<float>(b) * cell_mm_, z_hi = z_lo + cell_mm_;
            const float rc = 0.5f * (r_lo + r_hi), zc = 0.5f * (z_lo + z_hi);
            const float half_diag = 0.5f * std::sqrt(2.0f) * cell_mm_;
            float bound = std::numeric_limits<float>::max();
            for (std::size_t k = 0; k < segs_.size(); ++k) {
                float t;
                const float dc = std::sqrt(segs_[k].distance2(rc, zc, t));
                dmin[k] = std::max(0.0f, dc - half_diag);
                bound = std::min(bound, dc + half_diag);
            }
            cell_begin_[static_cast<std::size_t>(a * nz_ + b)] =
                static_cast<std::uint32_t>(cell_segs_.size());
            for (std::size_t k = 0; k < segs_.size(); ++k)
                if (dmin[k] <= bound) cell_segs_.push_back(static_cast<std::uint16_t>(k));
        }
    cell_begin_.back() = static_cast<std::uint32_t>(cell_segs_.size());
}

bool Surface::inside_region(const Eigen::Vector3f& q, float scale, float margin) const {
    if (model_.axisymmetric) {
        const float rm = scale * hi_.x() + margin;
        return q.x() * q.x() + q.y() * q.y() <= rm * rm && q.z() >= scale * lo_.z() - margin &&
               q.z() <= scale * hi_.z() + margin;
    }
    return (q.array() >= scale * lo_.array() - margin).all() &&
           (q.array() <= scale * hi_.array() + margin).all();
}

Surface::~Surface() { delete tree_; }

Closest Surface::closest(const Eigen::Vector3f& q, float scale) const {
    if (tree_) {
        const Eigen::Vector3f qs = q / scale;
        int idx = 0;
        float d2 = 0;
        flann::Matrix<float> query(const_cast<float*>(qs.data()), 1, 3);
        flann::Matrix<int> indices(&idx, 1, 1);
        flann::Matrix<float> dists(&d2, 1, 1);
        tree_->index.knnSearch(query, indices, dists, 1, flann::SearchParams(-1));
        const Eigen::Vector3f p = scale * model_.dense_points[static_cast<std::size_t>(idx)];
        const Eigen::Vector3f& n = model_.dense_normals[static_cast<std::size_t>(idx)];
        // Distance to the surface, not to the nearest sample: across the tangent plane, plus
        // what lies beyond the sample spacing along it.
        const Eigen::Vector3f d = q - p;
        const float across = n.dot(d);
        const float along = std::max(0.0f, (d - across * n).norm() - scale * dense_spacing_);
        return {p, n, std::sqrt(across * across + along * along)};
    }
    return closest_profile(q, scale);
}

Closest Surface::closest_profile(const Eigen::Vector3f& q, float scale) const {
    const float r = std::sqrt(q.x() * q.x() + q.y() * q.y());
    const float rs = r / scale, zs = q.z() / scale;
    float best = std::numeric_limits<float>::max(), t_best = 0;
    int seg = -1;
    const int a = static_cast<int>((rs - r0_) / cell_mm_),
              b = static_cast<int>((zs - z0_) / cell_mm_);
    const bool in_grid = rs >= r0_ && zs >= z0_ && a < nr_ && b < nz_;
    const std::size_t c = in_grid ? static_cast<std::size_t>(a * nz_ + b) : 0;
    const std::size_t k0 = in_grid ? cell_begin_[c] : 0;
    const std::size_t k1 = in_grid ? cell_begin_[c + 1] : segs_.size();
    // The nearest by distance, the first of equals. The root is taken only for a segment whose
    // squared distance is smaller than the best's (a necessary condition, the root rounding
    // monotonically). Not sufficient: two squared distances can round to the same root, and
    // then the first segment must stay the nearest, as it was when roots were compared.
    float best2 = std::numeric_limits<float>::infinity();
    for (std::size_t k = k0; k < k1; ++k) {
        const std::size_t si = in_grid ? cell_segs_[k] : k;
        float t;
        const float d2 = segs_[si].distance2(rs, zs, t);
        if (!(d2 < best2)) continue;
        if (const float d = std::sqrt(d2); d < best) {
            best = d;
            best2 = d2;
            t_best = t;
            seg = static_cast<int>(si);
        }
    }
    if (seg < 0)  // no segment at a finite distance (a non-finite query)
        return {q, Eigen::Vector3f::UnitZ(), std::numeric_limits<float>::infinity(), -1};
    const Seg& g = segs_[static_cast<std::size_t>(seg)];
    const float cr = g.r0 + t_best * g.ur, cz = g.z0 + t_best * g.uz;
    const bool corner = t_best <= 0.0f || t_best >= g.len;
    const float cx = r > 1e-6f ? q.x() / r : 1.0f, cy = r > 1e-6f ? q.y() / r : 0.0f;
    const Eigen::Vector3f p(scale * cr * cx, scale * cr * cy, scale * cz);
    // Beyond an edge the closest point is the edge itself and the distance grows in every
    // direction away from it: the residual direction is then q − p (the gradient of the
    // distance), so that points past an edge pull the part back instead of sliding along a plane.
    Eigen::Vector3f n(g.nr * cx, g.nr * cy, g.nz);
    if (corner) {
        const float dr = rs - cr, dz = zs - cz;
        const float len = std::sqrt(dr * dr + dz * dz);
        if (len > 1e-4f) n = Eigen::Vector3f(dr / len * cx, dr / len * cy, dz / len);
    }
    return {p, n, (q - p).norm(), seg, scale * (t_best - 0.5f * g.len), {cx, cy}};
}

namespace {

// The walls' nuisance unknowns when ICP frees them (IcpOptions::free_radii): each wall's offset δ
// along its normal and tilt β about its middle, in columns `first + 2j` and `first + 2j + 1`. A
// wall's own segment moves with both; the fillet chords joined to it end to end (up to a flat or
// another wall) with its offset.
class Walls {
  public:
    Walls(const Model& model, bool free, int first) : first_(first) {
        const auto& p = model.profile;
        wall_.assign(p.size(), -1);
        normal_.assign(p.size(), Eigen::Vector2f::Zero());
        own_.assign(p.size(), 0);
        if (!free) return;
        auto chord_of = [&](std::size_t a, std::size_t b) {  // b: a fillet chord joined to a
            const bool joined = a < b ? p[a].r1 == p[b].r0 && p[a].z1 == p[b].z0
                                      : p[b].r1 == p[a].r0 && p[b].z1 == p[a].z0;
            return joined && p[b].fillet_chord() && wall_[b] < 0;
        };
        for (std::size_t k = 0; k < p.size(); ++k) {
            if (!p[k].wall) continue;
            const double len = p[k].length();
            const Eigen::Vector2f n(static_cast<float>((p[k].z1 - p[k].z0) / len),
                                    static_cast<float>((p[k].r0 - p[k].r1) / len));
            auto claim = [&](std::size_t q) {
                wall_[q] = n_;
                normal_[q] = n;
            };
            claim(k);
            own_[k] = 1;
            for (std::size_t q = k; q > 0 && chord_of(q, q - 1); --q) claim(q - 1);
            for (std::size_t q = k; q + 1 < p.size() && chord_of(q, q + 1); ++q) claim(q + 1);
            ++n_;
        }
        delta_.assign(static_cast<std::size_t>(n_), 0.0);
        beta_.assign(static_cast<std::size_t>(n_), 0.0);
    }
    int unknowns() const { return 2 * n_; }

    // The correspondence's wall (−1: none), ∂e/∂δ (the share of the wall's normal motion along
    // its residual's direction) and ∂e/∂β (the tilt's lever).
    struct Term {
        int j = -1;
        float d_delta = 0, d_beta = 0;
    };
    Term term(const Closest& c) const {
        Term t;
        if (c.segment < 0) return t;
        const auto k = static_cast<std::size_t>(c.segment);
        t.j = wall_[k];
        if (t.j < 0) return t;
        const Eigen::Vector2f& nw = normal_[k];
        const Eigen::Vector3f n3(nw.x() * c.radial.x(), nw.x() * c.radial.y(), nw.y());
        t.d_delta = -c.normal.dot(n3);
        t.d_beta = own_[k] ? t.d_delta * c.along : 0.0f;
        return t;
    }
    // Point-to-plane residual of q against c, with the walls where they are now.
    float residual(const Closest& c, const Eigen::Vector3f& q) const {
        const float e = c.normal.dot(q - c.point);
        const Term t = term(c);
        if (t.j < 0) return e;
        const auto w = static_cast<std::size_t>(t.j);
        return e + static_cast<float>(t.d_delta * delta_[w] + t.d_beta * beta_[w]);
    }
    // One correspondence's share of the normal equations: its wall's columns, and their coupling
    // to the pose's (J, the pose's first `n_pose` derivatives).
    template <class Jac>
    void add(const Closest& c, const Jac& J, int n_pose, double w, double e, Eigen::MatrixXd& H,
             Eigen::VectorXd& g) const {
        const Term t = term(c);
        if (t.j < 0) return;
        const int col = first_ + 2 * t.j;
        const double jd = t.d_delta, jb = t.d_beta;
        for (int a = 0; a < n_pose; ++a) {
            H(a, col) += w * J(a) * jd;
            H(a, col + 1) += w * J(a) * jb;
        }
        H(col, col) += w * jd * jd;
        H(col, col + 1) += w * jd * jb;
        H(col + 1, col + 1) += w * jb * jb;
        g(col) += w * e * jd;
        g(col + 1) += w * e * jb;
    }
    // Weak priors: a wall that no point sees keeps its offset and tilt at zero.
    void add_priors(Eigen::MatrixXd& H) const {
        constexpr double kOffsetPrior = 1.0;     // as weak as one point on the wall
        constexpr double kTiltPriorMm2 = 100.0;  // as weak as one point 10 mm along
        for (int j = 0; j < n_; ++j) {
            H(first_ + 2 * j, first_ + 2 * j) += kOffsetPrior;
            H(first_ + 2 * j + 1, first_ + 2 * j + 1) += kTiltPriorMm2;
        }
    }
    void update(const Eigen::VectorXd& x) {
        for (int j = 0; j < n_; ++j) {
            delta_[static_cast<std::size_t>(j)] += x(first_ + 2 * j);
            beta_[static_cast<std::size_t>(j)] += x(first_ + 2 * j + 1);
        }
    }

  private:
    int first_, n_ = 0;
    std::vector<int> wall_;                // per segment: its wall's index, or −1
    std::vector<Eigen::Vector2f> normal_;  // per segment: that wall's outward (r, z) normal
    std::vector<char> own_;                // per segment: it is the wall itself
    std::vector<double> delta_, beta_;
};

// The pose step x (ω over the first n_rot entries, then v, then the log scale when estimated)
// applied to the part frame (q' = D·q: T_part_world ← D·T_part_world); returns how far it moves
// the part's farthest point.
double apply_step(const Eigen::VectorXd& x, int n_rot, bool estimate_scale, double half_size,
                  Eigen::Isometry3d& T_world_part, double& scale) {
    Eigen::Vector3d w = Eigen::Vector3d::Zero();
    for (int a = 0; a < n_rot; ++a) w(a) = x(a);
    const Eigen::Vector3d v = x.segment<3>(n_rot);
    Eigen::Isometry3d D = Eigen::Isometry3d::Identity();
    if (w.norm() > 0) D.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
    D.translation() = v;
    T_world_part = (D * T_world_part.inverse()).inverse();
    const double log_scale = estimate_scale ? x(n_rot + 3) : 0.0;
    scale *= std::exp(log_scale);
    return w.norm() * half_size + v.norm() + std::abs(log_scale) * half_size;
}

// Tuning of the robust Gauss–Newton step (docs/matching.md, "ICP").
// Fewer gated residuals than this give no trustworthy median: the fit has lost the part.
constexpr std::size_t kMinGatedResiduals = 12;
// σ̂ = 1.4826 · MAD: the MAD of normally distributed residuals is 0.6745 σ.
constexpr float kMadToSigma = 1.4826f;
// σ̂'s floor: on a near-perfect fit the MAD tends to 0 and the kernel would reject every point.
constexpr float kMinSigmaMm = 0.01f;
// Tukey's biweight c = 4.685 σ̂: 95 % efficiency on normally distributed residuals.
constexpr float kTukeyC = 4.685f;
// A step needs this many used points per pose unknown; fewer leave it poorly determined.
constexpr int kMinPointsPerUnknown = 4;
// Damping relative to H's largest diagonal entry: enough to keep H positive definite, far too
// small to bias a direction the data fix.
constexpr double kRelativeDamping = 1e-9;
// The pose unknowns at most: ω (3), v (3), log scale.
constexpr int kMaxPoseUnknowns = 7;

// Unknowns: rotation ω and translation v of the part frame (scene side), log scale, and the
// walls' offsets and tilts (Walls). Axisymmetric: the spin ω_z is unobservable and left out.
struct Unknowns {
    int n_rot = 3;   // ω's entries
    int n_pose = 6;  // ω, v and the log scale when estimated
    int n_par = 6;   // with the walls'
    bool estimate_scale = false;
};

// Each scene point in the part frame, its closest model point, and the |residual| of those
// within the gate.
struct Correspondences {
    std::vector<Eigen::Vector3f> q_part;
    std::vector<Closest> closest;
    std::vector<float> gated_abs_mm;
};

void correspond(const Surface& surface, const Walls& walls, const std::vector<Eigen::Vector3f>& pts,
                const Eigen::Isometry3d& T_world_part, double scale, float gate,
                Correspondences& corr) {
    const Eigen::Isometry3f T_pw = T_world_part.inverse().cast<float>();
    const auto s = static_cast<float>(scale);
    corr.gated_abs_mm.clear();
    for (std::size_t i = 0; i < pts.size(); ++i) {
        corr.q_part[i] = T_pw * pts[i];
        corr.closest[i] = surface.closest(corr.q_part[i], s);
        if (corr.closest[i].distance < gate)
            corr.gated_abs_mm.push_back(std::abs(walls.residual(corr.closest[i], corr.q_part[i])));
    }
}

// Residual scale for the robust kernel: Tukey's c from the MAD of the gated residuals (which it
// reorders); none when too few lie within the gate.
std::optional<float> tukey_threshold(std::vector<float>& gated_abs_mm) {
    if (gated_abs_mm.size() < kMinGatedResiduals) return std::nullopt;
    std::nth_element(gated_abs_mm.begin(), gated_abs_mm.begin() + gated_abs_mm.size() / 2,
                     gated_abs_mm.end());
    const float sigma = std::max(kMinSigmaMm, kMadToSigma * gated_abs_mm[gated_abs_mm.size() / 2]);
    return kTukeyC * sigma;
}

// Normal equations H x = −g (H's upper triangle) of the Tukey-weighted point-to-plane residuals.
struct NormalEquations {
    Eigen::MatrixXd H;
    Eigen::VectorXd g;
    double sw = 0, swe2 = 0;  // Σ w and Σ w e² over the points used
    std::int64_t used = 0;
};

// Each point within the gate and the kernel touches the pose block and at most one wall.
NormalEquations normal_equations(const Correspondences& corr, const Walls& walls,
                                 const Unknowns& unk, float gate, float c) {
    NormalEquations ne{Eigen::MatrixXd::Zero(unk.n_par, unk.n_par),
                       Eigen::VectorXd::Zero(unk.n_par)};
    Eigen::Matrix<double, kMaxPoseUnknowns, 1> J =
        Eigen::Matrix<double, kMaxPoseUnknowns, 1>::Zero();
    for (std::size_t i = 0; i < corr.closest.size(); ++i) {
        const Closest& cl = corr.closest[i];
        if (cl.distance >= gate) continue;
        const Eigen::Vector3f& n = cl.normal;
        const float e = walls.residual(cl, corr.q_part[i]);
        if (std::abs(e) >= c) continue;
        const float u = e / c;
        const double w = (1.0f - u * u) * (1.0f - u * u);
        const Eigen::Vector3f qxn = corr.q_part[i].cross(n);
        for (int a = 0; a < unk.n_rot; ++a) J(a) = qxn(a);
        for (int a = 0; a < 3; ++a) J(unk.n_rot + a) = n(a);
        if (unk.estimate_scale) J(unk.n_pose - 1) = -n.dot(cl.point);
        for (int a = 0; a < unk.n_pose; ++a) {
            const double wja = w * J(a);
            for (int b = a; b < unk.n_pose; ++b) ne.H(a, b) += wja * J(b);
            ne.g(a) += wja * e;
        }
        walls.add(cl, J, unk.n_pose, w, e, ne.H, ne.g);
        ne.sw += w;
        ne.swe2 += w * e * e;
        ++ne.used;
    }
    return ne;
}

// The step x: H x = −g with the walls' weak priors and a tiny damping, which keeps a direction
// the data do not fix (the spin of a symmetric part under a general model) from drifting.
Eigen::VectorXd solve_step(const Walls& walls, const Unknowns& unk, NormalEquations& ne) {
    walls.add_priors(ne.H);
    const double damping = kRelativeDamping * ne.H.diagonal().maxCoeff();
    for (int a = 0; a < unk.n_par; ++a) ne.H(a, a) += damping;
    const Eigen::MatrixXd Hs = ne.H.selfadjointView<Eigen::Upper>();
    return Hs.ldlt().solve(-ne.g);
}

}  // namespace

IcpResult icp(const Surface& surface, const Model& model, const std::vector<Eigen::Vector3f>& pts,
              Eigen::Isometry3d T_world_part, double scale, const IcpOptions& o) {
    IcpResult res;
    const bool axi = model.axisymmetric;
    Unknowns unk;
    unk.n_rot = axi ? 2 : 3;
    unk.n_pose = unk.n_rot + 3 + (o.estimate_scale ? 1 : 0);
    unk.estimate_scale = o.estimate_scale;
    Walls walls(model, axi && o.free_radii, unk.n_pose);
    unk.n_par = unk.n_pose + walls.unknowns();
    Correspondences corr;
    corr.q_part.resize(pts.size());
    corr.closest.resize(pts.size());
    int it = 0;
    // Stages of narrowing correspondence gates; in each, Gauss–Newton steps until the part stops
    // moving.
    for (std::size_t stage = 0; stage < o.gates_mm.size(); ++stage) {
        const float gate = static_cast<float>(o.gates_mm[stage]);
        for (int k = 0; k < o.iterations_per_stage && it < o.max_iterations; ++k, ++it) {
            // 1. Correspondences: the closest model point of each scene point.
            correspond(surface, walls, pts, T_world_part, scale, gate, corr);
            // 2. The robust kernel's width from the gated residuals.
            const std::optional<float> c = tukey_threshold(corr.gated_abs_mm);
            if (!c) break;
            // 3. The weighted normal equations.
            NormalEquations ne = normal_equations(corr, walls, unk, gate, *c);
            res.used = ne.used;
            res.rms_mm = ne.sw > 0 ? std::sqrt(ne.swe2 / ne.sw) : 0;
            if (ne.used < unk.n_pose * kMinPointsPerUnknown) break;
            // 4. Solve, and move the part (and the walls).
            const Eigen::VectorXd x = solve_step(walls, unk, ne);
            if (!x.allFinite()) break;
            const double motion = apply_step(x, unk.n_rot, o.estimate_scale, surface.half_size(),
                                             T_world_part, scale);
            walls.update(x);
            if (motion < o.stop_mm && k > 0) break;
        }
    }
    res.T_world_part = T_world_part;
    res.scale = scale;
    res.iterations = it;
    return res;
}

Support support(const Surface& surface, const std::vector<Eigen::Vector3f>& pts,
                const Eigen::Isometry3d& T_world_part, double scale, double band_mm,
                double margin_mm) {
    Support s;
    const Eigen::Isometry3f T_pw = T_world_part.inverse().cast<float>();
    const auto sc = static_cast<float>(scale);
    const auto margin = static_cast<float>(margin_mm), band = static_cast<float>(band_mm);
    for (const auto& p : pts) {
        const Eigen::Vector3f q = T_pw * p;
        // The region test first: the closest point is the costly part, and most scan points
        // (the plate, the other faces' surroundings) lie outside the part's region.
        if (!surface.inside_region(q, sc, margin)) continue;
        ++s.near;
        s.inliers += surface.closest(q, sc).distance < band;
    }
    return s;
}

}  // namespace hotgauge::match::detail

namespace hotgauge::match {

SurfaceCache& SurfaceCache::operator=(const SurfaceCache&) {
    std::lock_guard lock(mutex_);
    surface_.reset();  // it was this model's old data's
    return *this;
}

SurfaceCache& SurfaceCache::operator=(SurfaceCache&&) noexcept {
    std::lock_guard lock(mutex_);
    surface_.reset();
    return *this;
}

SurfaceCache::~SurfaceCache() = default;

std::shared_ptr<const detail::Surface> SurfaceCache::get(const Model& model) const {
    std::lock_guard lock(mutex_);
    if (!surface_) surface_ = std::make_shared<const detail::Surface>(model);
    return surface_;
}

}  // namespace hotgauge::match
