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
            const auto r = static_cast<float>(s.cylinder ? s.value : s.hi);
            hi_.x() = std::max(hi_.x(), r);
            lo_.z() = std::min(lo_.z(), static_cast<float>(s.cylinder ? s.lo : s.value));
            hi_.z() = std::max(hi_.z(), static_cast<float>(s.cylinder ? s.hi : s.value));
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

namespace {

// Distance from (r, z) to a segment, and the segment's farthest point from a cell's corners.
float seg_distance(float r, float z, bool cylinder, float value, float lo, float hi) {
    const float along = cylinder ? z : r, across = cylinder ? r : z;
    const float d_along = along < lo ? lo - along : (along > hi ? along - hi : 0.0f);
    return std::sqrt(d_along * d_along + (across - value) * (across - value));
}

}  // namespace

void Surface::build_profile_grid() {
    for (const auto& s : model_.profile)
        segs_.push_back({s.cylinder, static_cast<float>(s.value), static_cast<float>(s.lo),
                         static_cast<float>(s.hi)});
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
                const Seg& g = segs_[k];
                const float dc = seg_distance(rc, zc, g.cylinder, g.value, g.lo, g.hi);
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
    float best = std::numeric_limits<float>::max();
    float cr = 0, cz = 0;
    bool cyl = false, corner = false;
    int seg = -1;
    const int a = static_cast<int>((rs - r0_) / cell_mm_),
              b = static_cast<int>((zs - z0_) / cell_mm_);
    const bool in_grid = rs >= r0_ && zs >= z0_ && a < nr_ && b < nz_;
    const std::size_t c = in_grid ? static_cast<std::size_t>(a * nz_ + b) : 0;
    const std::size_t k0 = in_grid ? cell_begin_[c] : 0;
    const std::size_t k1 = in_grid ? cell_begin_[c + 1] : segs_.size();
    for (std::size_t k = k0; k < k1; ++k) {
        const std::size_t si = in_grid ? cell_segs_[k] : k;
        const Seg& s = segs_[si];
        const float lo = s.lo, hi = s.hi, v = s.value;
        float pr, pz;
        if (s.cylinder) {
            pr = v;
            pz = std::clamp(zs, lo, hi);
        } else {
            pr = std::clamp(rs, lo, hi);
            pz = v;
        }
        const float d2 = (pr - rs) * (pr - rs) + (pz - zs) * (pz - zs);
        if (d2 < best) {
            best = d2;
            cr = pr;
            cz = pz;
            cyl = s.cylinder;
            corner = (s.cylinder ? pz : pr) == lo || (s.cylinder ? pz : pr) == hi;
            seg = static_cast<int>(si);
        }
    }
    const float cx = r > 1e-6f ? q.x() / r : 1.0f, cy = r > 1e-6f ? q.y() / r : 0.0f;
    const Eigen::Vector3f p(scale * cr * cx, scale * cr * cy, scale * cz);
    // Beyond an edge the closest point is the edge itself and the distance grows in every
    // direction away from it: the residual direction is then q − p (the gradient of the
    // distance), so that points past an edge pull the part back instead of sliding along a plane.
    Eigen::Vector3f n = cyl ? Eigen::Vector3f(cx, cy, 0.0f) : Eigen::Vector3f::UnitZ();
    if (corner) {
        const float dr = rs - cr, dz = zs - cz;
        const float len = std::sqrt(dr * dr + dz * dz);
        if (len > 1e-4f) n = Eigen::Vector3f(dr / len * cx, dr / len * cy, dz / len);
    }
    return {p, n, (q - p).norm(), corner ? -1 : seg};
}

IcpResult icp(const Surface& surface, const Model& model, const std::vector<Eigen::Vector3f>& pts,
              Eigen::Isometry3d T_world_part, double scale, const IcpOptions& o) {
    IcpResult res;
    // Unknowns: rotation ω and translation v of the part frame (scene side), log scale, and the
    // cylinders' radius offsets. Axisymmetric: the spin ω_z is unobservable and left out.
    const bool axi = model.axisymmetric;
    const int n_rot = axi ? 2 : 3;
    const int n_pose = n_rot + 3 + (o.estimate_scale ? 1 : 0);
    // Offset unknown of each profile segment (−1: none).
    std::vector<int> offset_of(model.profile.size(), -1);
    int n_off = 0;
    if (axi && o.free_radii)
        for (std::size_t k = 0; k < model.profile.size(); ++k)
            if (model.profile[k].cylinder) offset_of[k] = n_off++;
    const int n_par = n_pose + n_off;
    std::vector<double> delta(static_cast<std::size_t>(n_off), 0.0);
    auto offset = [&](const Closest& c) {
        const int j = c.segment >= 0 ? offset_of[static_cast<std::size_t>(c.segment)] : -1;
        return j;
    };
    const double half_size = surface.half_size();
    std::vector<float> resid;
    std::vector<Closest> cs(pts.size());
    std::vector<Eigen::Vector3f> qs(pts.size());
    int it = 0;
    for (std::size_t stage = 0; stage < o.gates_mm.size(); ++stage) {
        const float gate = static_cast<float>(o.gates_mm[stage]);
        for (int k = 0; k < o.iterations_per_stage && it < o.max_iterations; ++k, ++it) {
            const Eigen::Isometry3f T_pw = T_world_part.inverse().cast<float>();
            const auto s = static_cast<float>(scale);
            auto residual = [&](std::size_t i) {
                const int j = offset(cs[i]);
                return cs[i].normal.dot(qs[i] - cs[i].point) -
                       (j >= 0 ? static_cast<float>(delta[static_cast<std::size_t>(j)]) : 0.0f);
            };
            // Residual scale for the robust kernel: MAD of the gated residuals.
            resid.clear();
            for (std::size_t i = 0; i < pts.size(); ++i) {
                qs[i] = T_pw * pts[i];
                cs[i] = surface.closest(qs[i], s);
                if (cs[i].distance < gate) resid.push_back(std::abs(residual(i)));
            }
            if (resid.size() < 12) break;
            std::nth_element(resid.begin(), resid.begin() + resid.size() / 2, resid.end());
            const float sigma = std::max(0.01f, 1.4826f * resid[resid.size() / 2]);
            const float c = 4.685f * sigma;  // Tukey biweight
            // Normal equations; each point touches the pose block and at most one offset.
            Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n_par, n_par);
            Eigen::VectorXd g = Eigen::VectorXd::Zero(n_par);
            Eigen::Matrix<double, 6, 1> J = Eigen::Matrix<double, 6, 1>::Zero();
            double sw = 0, swe2 = 0;
            std::int64_t used = 0;
            for (std::size_t i = 0; i < pts.size(); ++i) {
                if (cs[i].distance >= gate) continue;
                const Eigen::Vector3f& n = cs[i].normal;
                const float e = residual(i);
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
                if (const int j = offset(cs[i]); j >= 0) {  // ∂e/∂δ = −1
                    const int col = n_pose + j;
                    for (int a = 0; a < n_pose; ++a) H(a, col) -= w * J(a);
                    H(col, col) += w;
                    g(col) -= w * e;
                }
                sw += w;
                swe2 += w * e * e;
                ++used;
            }
            res.used = used;
            res.rms_mm = sw > 0 ? std::sqrt(swe2 / sw) : 0;
            if (used < n_pose * 4) break;
            // A weak prior keeps the offset of a cylinder that no point sees at zero; a tiny
            // damping keeps a direction the data do not fix (the spin of a symmetric part under a
            // general model) from drifting.
            for (int j = 0; j < n_off; ++j) H(n_pose + j, n_pose + j) += 1.0;
            const double damping = 1e-9 * H.diagonal().maxCoeff();
            for (int a = 0; a < n_par; ++a) H(a, a) += damping;
            const Eigen::MatrixXd Hs = H.selfadjointView<Eigen::Upper>();
            const Eigen::VectorXd x = Hs.ldlt().solve(-g);
            if (!x.allFinite()) break;
            Eigen::Vector3d w = Eigen::Vector3d::Zero();
            for (int a = 0; a < n_rot; ++a) w(a) = x(a);
            const Eigen::Vector3d v = x.segment<3>(n_rot);
            Eigen::Isometry3d D = Eigen::Isometry3d::Identity();
            if (w.norm() > 0)
                D.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
            D.translation() = v;
            // q' = D·q: the part frame is updated as T_part_world ← D·T_part_world.
            T_world_part = (D * T_world_part.inverse()).inverse();
            if (o.estimate_scale) scale *= std::exp(x(n_pose - 1));
            for (int j = 0; j < n_off; ++j) delta[static_cast<std::size_t>(j)] += x(n_pose + j);
            const double motion = w.norm() * half_size + v.norm() +
                                  (o.estimate_scale ? std::abs(x(n_pose - 1)) * half_size : 0.0);
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
