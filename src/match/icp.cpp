// Robust point-to-plane ICP against the model surface (docs/matching.md). Axisymmetric models use
// the exact (r, z) profile: the closest point is found in the meridian half-plane, with no
// sampling error and no tree; other models use a FLANN k-d tree over their dense samples.
#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <flann/flann.hpp>

#include "internal.hpp"

namespace hotgauge::match::detail {

struct Surface::KdTree {
    flann::Matrix<float> data;
    flann::Index<flann::L2_Simple<float>> index;
    explicit KdTree(const std::vector<Eigen::Vector3f>& pts)
        : data(const_cast<float*>(pts.front().data()), pts.size(), 3, sizeof(Eigen::Vector3f)),
          index(data, flann::KDTreeSingleIndexParams(15)) {
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
            const std::size_t step = std::max<std::size_t>(1, model.dense_points.size() / 500);
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

float Surface::Seg::distance(float r, float z, float& t) const {
    t = std::clamp((r - r0) * ur + (z - z0) * uz, 0.0f, len);
    const float dr = r0 + t * ur - r, dz = z0 + t * uz - z;
    return std::sqrt(dr * dr + dz * dz);
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
                const float dc = segs_[k].distance(rc, zc, t);
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
    for (std::size_t k = k0; k < k1; ++k) {
        const std::size_t si = in_grid ? cell_segs_[k] : k;
        float t;
        const float d = segs_[si].distance(rs, zs, t);
        if (d < best) {
            best = d;
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
        constexpr double kTiltPriorMm2 = 100.0;  // as weak as one point 10 mm along
        for (int j = 0; j < n_; ++j) {
            H(first_ + 2 * j, first_ + 2 * j) += 1.0;
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

}  // namespace

IcpResult icp(const Surface& surface, const Model& model, const std::vector<Eigen::Vector3f>& pts,
              Eigen::Isometry3d T_world_part, double scale, const IcpOptions& o) {
    IcpResult res;
    // Unknowns: rotation ω and translation v of the part frame (scene side), log scale, and the
    // walls' offsets and tilts (Walls). Axisymmetric: the spin ω_z is unobservable and left out.
    const bool axi = model.axisymmetric;
    const int n_rot = axi ? 2 : 3;
    const int n_pose = n_rot + 3 + (o.estimate_scale ? 1 : 0);
    Walls walls(model, axi && o.free_radii, n_pose);
    const int n_par = n_pose + walls.unknowns();
    std::vector<float> resid;
    std::vector<Closest> cs(pts.size());
    std::vector<Eigen::Vector3f> qs(pts.size());
    int it = 0;
    for (std::size_t stage = 0; stage < o.gates_mm.size(); ++stage) {
        const float gate = static_cast<float>(o.gates_mm[stage]);
        for (int k = 0; k < o.iterations_per_stage && it < o.max_iterations; ++k, ++it) {
            const Eigen::Isometry3f T_pw = T_world_part.inverse().cast<float>();
            const auto s = static_cast<float>(scale);
            // Residual scale for the robust kernel: MAD of the gated residuals.
            resid.clear();
            for (std::size_t i = 0; i < pts.size(); ++i) {
                qs[i] = T_pw * pts[i];
                cs[i] = surface.closest(qs[i], s);
                if (cs[i].distance < gate) resid.push_back(std::abs(walls.residual(cs[i], qs[i])));
            }
            if (resid.size() < 12) break;
            std::nth_element(resid.begin(), resid.begin() + resid.size() / 2, resid.end());
            const float sigma = std::max(0.01f, 1.4826f * resid[resid.size() / 2]);
            const float c = 4.685f * sigma;  // Tukey biweight
            // Normal equations; each point touches the pose block and at most one wall.
            Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n_par, n_par);
            Eigen::VectorXd g = Eigen::VectorXd::Zero(n_par);
            Eigen::Matrix<double, 6, 1> J = Eigen::Matrix<double, 6, 1>::Zero();
            double sw = 0, swe2 = 0;
            std::int64_t used = 0;
            for (std::size_t i = 0; i < pts.size(); ++i) {
                if (cs[i].distance >= gate) continue;
                const Eigen::Vector3f& n = cs[i].normal;
                const float e = walls.residual(cs[i], qs[i]);
                if (std::abs(e) >= c) continue;
                const float u = e / c;
                const double w = (1.0f - u * u) * (1.0f - u * u);
                const Eigen::Vector3f qxn = qs[i].cross(n);
                for (int a = 0; a < n_rot; ++a) J(a) = qxn(a);
                for (int a = 0; a < 3; ++a) J(n_rot + a) = n(a);
                if (o.estimate_scale) J(n_pose - 1) = -n.dot(cs[i].point);
                for (int a = 0; a < n_pose; ++a) {
                    const double wja = w * J(a);
                    for (int b = a; b < n_pose; ++b) H(a, b) += wja * J(b);
                    g(a) += wja * e;
                }
                walls.add(cs[i], J, n_pose, w, e, H, g);
                sw += w;
                swe2 += w * e * e;
                ++used;
            }
            res.used = used;
            res.rms_mm = sw > 0 ? std::sqrt(swe2 / sw) : 0;
            if (used < n_pose * 4) break;
            // A tiny damping keeps a direction the data do not fix (the spin of a symmetric part
            // under a general model) from drifting.
            walls.add_priors(H);
            const double damping = 1e-9 * H.diagonal().maxCoeff();
            for (int a = 0; a < n_par; ++a) H(a, a) += damping;
            const Eigen::MatrixXd Hs = H.selfadjointView<Eigen::Upper>();
            const Eigen::VectorXd x = Hs.ldlt().solve(-g);
            if (!x.allFinite()) break;
            const double motion =
                apply_step(x, n_rot, o.estimate_scale, surface.half_size(), T_world_part, scale);
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
