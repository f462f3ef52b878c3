// ForgedSolid: ray casting on two solids of revolution whose profiles are polylines. Each
// profile segment revolves into a cone frustum (an annulus when horizontal, a cylinder when
// vertical); with the segment's line a·r + b·z + c = 0, a ray o + t·d meets the cone where
// a²·(x² + y²) = (b·z + c)², a quadratic in t (its second root on the mirror cone is dropped).
#include <algorithm>
#include <cmath>
#include <limits>

#include "hotgauge/core/forged.hpp"

namespace hotgauge::core {
namespace {

constexpr double kMinT = 1e-9;
constexpr double kEdge = 1e-9;         // mm: a hit this far past a segment's end still counts
constexpr double kOnLine = 1e-5;       // mm: off the segment's line by more: the mirror cone
constexpr double kBoxPad = 1e-7;       // mm
constexpr std::size_t kGroupSize = 8;  // segments per bounding box

// The ray relative to a half's axis: r²(t) = c2 + 2·b2·t + a2·t².
struct AxisRay {
    double ox, oy, oz, dx, dy, dz, a2, b2, c2;
    AxisRay(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector2d& axis)
        : ox(o.x() - axis.x()),
          oy(o.y() - axis.y()),
          oz(o.z()),
          dx(d.x()),
          dy(d.y()),
          dz(d.z()),
          a2(dx * dx + dy * dy),
          b2(ox * dx + oy * dy),
          c2(ox * ox + oy * oy) {}
    double r2(double t) const { return c2 + 2.0 * b2 * t + a2 * t * t; }
};

// Whether the ray can meet anything in the revolved box r in [r_lo, r_hi], z in [z_lo, z_hi]
// for t in (kMinT, t_max).
template <class Box>
bool may_hit(const Box& g, const AxisRay& ray, double t_max) {
    double ta = kMinT, tb = t_max;
    if (ray.dz == 0.0) {
        if (ray.oz < g.z_lo || ray.oz > g.z_hi) return false;
    } else {
        double t1 = (g.z_lo - ray.oz) / ray.dz, t2 = (g.z_hi - ray.oz) / ray.dz;
        if (t1 > t2) std::swap(t1, t2);
        ta = std::max(ta, t1);
        tb = std::min(tb, t2);
        if (ta > tb) return false;
    }
    // r² is convex in t: its largest value on [ta, tb] is at an end.
    if (std::max(ray.r2(ta), ray.r2(tb)) < g.r_lo * g.r_lo) return false;
    const double tm = ray.a2 > 0.0 ? std::clamp(-ray.b2 / ray.a2, ta, tb) : ta;
    return ray.r2(tm) <= g.r_hi * g.r_hi;
}

double segment_distance(double r, double z, double r0, double z0, double ur, double uz,
                        double len) {
    const double s = std::clamp((r - r0) * ur + (z - z0) * uz, 0.0, len);
    return std::hypot(r - (r0 + s * ur), z - (z0 + s * uz));
}

double radius_about(const Eigen::Vector3d& p, const Eigen::Vector2d& axis) {
    return std::hypot(p.x() - axis.x(), p.y() - axis.y());
}

}  // namespace

ForgedSolid::ForgedSolid(Profile lower, Profile upper, double parting_z_mm,
                         Eigen::Vector2d upper_axis_mm)
    : lower_(make_half(std::move(lower), Eigen::Vector2d::Zero())),
      upper_(make_half(std::move(upper), upper_axis_mm)),
      parting_z_(parting_z_mm) {}

ForgedSolid::Half ForgedSolid::make_half(Profile profile, const Eigen::Vector2d& axis) {
    Half h;
    h.axis = axis;
    for (std::size_t i = 0; i + 1 < profile.size(); ++i) {
        const Eigen::Vector2d p = profile[i], q = profile[i + 1];
        const double len = (q - p).norm();
        h.r_max = std::max({h.r_max, p.x(), q.x()});
        if (len <= 0.0 || (p.x() <= 0.0 && q.x() <= 0.0)) continue;  // on the axis: no surface
        const double ur = (q.x() - p.x()) / len, uz = (q.y() - p.y()) / len;
        // Material on the left: the outward normal is the right-hand one, (uz, −ur).
        h.segments.push_back({p.x(), p.y(), ur, uz, len, uz, -ur, -(uz * p.x() - ur * p.y())});
    }
    for (std::size_t i = 0; i < h.segments.size(); i += kGroupSize) {
        Group g{std::numeric_limits<double>::max(),
                std::numeric_limits<double>::lowest(),
                std::numeric_limits<double>::max(),
                std::numeric_limits<double>::lowest(),
                i,
                std::min(i + kGroupSize, h.segments.size())};
        for (std::size_t j = g.begin; j < g.end; ++j) {
            const Segment& s = h.segments[j];
            for (const double k : {0.0, s.len}) {
                g.r_lo = std::min(g.r_lo, s.r0 + k * s.ur - kBoxPad);
                g.r_hi = std::max(g.r_hi, s.r0 + k * s.ur + kBoxPad);
                g.z_lo = std::min(g.z_lo, s.z0 + k * s.uz - kBoxPad);
                g.z_hi = std::max(g.z_hi, s.z0 + k * s.uz + kBoxPad);
            }
        }
        h.groups.push_back(g);
    }
    if (!profile.empty()) {
        h.r_in = std::min(profile.front().x(), profile.back().x());
        h.r_out = std::max(profile.front().x(), profile.back().x());
    }
    h.profile = std::move(profile);
    return h;
}

std::optional<AxisymmetricSolid::Hit> ForgedSolid::intersect_half(const Half& h,
                                                                  const Eigen::Vector3d& o,
                                                                  const Eigen::Vector3d& d,
                                                                  double& t_best) const {
    const AxisRay ray(o, d, h.axis);
    if (ray.a2 > 0.0) {  // never within the half's bounding cylinder
        const double tc = -ray.b2 / ray.a2;
        if (ray.r2(tc) > h.r_max * h.r_max * 1.0000001) return std::nullopt;
    }
    const Segment* hit = nullptr;
    double r_hit = 0;
    auto take = [&](const Segment& s, double t) {
        if (!(t > kMinT && t < t_best)) return;
        const double z = ray.oz + t * ray.dz, r = std::sqrt(std::max(0.0, ray.r2(t)));
        const double along = (r - s.r0) * s.ur + (z - s.z0) * s.uz;
        if (along < -kEdge || along > s.len + kEdge) return;
        if (std::abs(s.a * r + s.b * z + s.c) > kOnLine) return;
        t_best = t;
        hit = &s;
        r_hit = r;
    };
    for (const Group& g : h.groups) {
        if (!may_hit(g, ray, t_best)) continue;
        for (std::size_t j = g.begin; j < g.end; ++j) {
            const Segment& s = h.segments[j];
            if (std::abs(s.a) < 1e-12) {  // an annulus z = z0
                if (ray.dz != 0.0) take(s, (s.z0 - ray.oz) / ray.dz);
                continue;
            }
            // a²·r²(t) = (P + Q·t)²  ->  qa·t² + 2·qb·t + qc = 0
            const double P = s.b * ray.oz + s.c, Q = s.b * ray.dz, a2 = s.a * s.a;
            const double qa = a2 * ray.a2 - Q * Q, qb = a2 * ray.b2 - P * Q,
                         qc = a2 * ray.c2 - P * P;
            if (std::abs(qa) < 1e-14) {
                if (qb != 0.0) take(s, -qc / (2.0 * qb));
                continue;
            }
            const double disc = qb * qb - qa * qc;
            if (disc < 0.0) continue;
            const double q = -(qb + std::copysign(std::sqrt(disc), qb));
            take(s, q / qa);
            if (q != 0.0) take(s, qc / q);
        }
    }
    if (!hit) return std::nullopt;
    const Eigen::Vector3d p = o + t_best * d;
    Eigen::Vector3d n(0.0, 0.0, hit->b);
    if (r_hit > 1e-12) {
        n.x() = hit->a * (p.x() - h.axis.x()) / r_hit;
        n.y() = hit->a * (p.y() - h.axis.y()) / r_hit;
    }
    return AxisymmetricSolid::Hit{t_best, n.normalized()};
}

// Whether a point of the parting plane is on exactly one half's annulus (a step the die shift
// leaves uncovered); `lower_face`: it is the lower half's top face.
bool ForgedSolid::on_parting_face(const Eigen::Vector3d& p, bool* lower_face) const {
    const double rl = radius_about(p, lower_.axis), ru = radius_about(p, upper_.axis);
    const bool in_lower = rl >= lower_.r_in && rl <= lower_.r_out;
    const bool in_upper = ru >= upper_.r_in && ru <= upper_.r_out;
    if (in_lower == in_upper) return false;
    *lower_face = in_lower;
    return true;
}

std::optional<AxisymmetricSolid::Hit> ForgedSolid::intersect(const Eigen::Vector3d& o,
                                                             const Eigen::Vector3d& d,
                                                             double t_max) const {
    double t_best = t_max;
    std::optional<AxisymmetricSolid::Hit> best = intersect_half(lower_, o, d, t_best);
    if (auto h = intersect_half(upper_, o, d, t_best)) best = h;
    if (d.z() != 0.0) {
        const double t = (parting_z_ - o.z()) / d.z();
        bool lower_face = false;
        if (t > kMinT && t < t_best && on_parting_face(o + t * d, &lower_face))
            best = AxisymmetricSolid::Hit{t, Eigen::Vector3d(0, 0, lower_face ? 1.0 : -1.0)};
    }
    return best;
}

bool ForgedSolid::inside(const Eigen::Vector3d& p) const {
    const Half& h = p.z() <= parting_z_ ? lower_ : upper_;
    const double r = radius_about(p, h.axis), z = p.z();
    bool in = false;  // even-odd crossings of the closed profile
    const std::size_t n = h.profile.size();
    for (std::size_t i = 0; i < n; ++i) {
        const Eigen::Vector2d& a = h.profile[i];
        const Eigen::Vector2d& b = h.profile[(i + 1) % n];
        if ((a.y() > z) != (b.y() > z) &&
            r < a.x() + (z - a.y()) * (b.x() - a.x()) / (b.y() - a.y()))
            in = !in;
    }
    return in;
}

double ForgedSolid::distance(const Eigen::Vector3d& p) const {
    double best = std::numeric_limits<double>::max();
    for (const Half* h : {&lower_, &upper_}) {
        const double r = radius_about(p, h->axis);
        for (const Segment& s : h->segments)
            best = std::min(best, segment_distance(r, p.z(), s.r0, s.z0, s.ur, s.uz, s.len));
    }
    bool lower_face = false;
    if (on_parting_face({p.x(), p.y(), parting_z_}, &lower_face))
        best = std::min(best, std::abs(p.z() - parting_z_));
    return best;
}

double ForgedSolid::max_radius() const {
    return std::max(lower_.r_max, upper_.r_max + upper_.axis.norm());
}

double ForgedSolid::bottom_radius() const {
    double z_min = std::numeric_limits<double>::max(), r = 0.0;
    for (const auto& q : lower_.profile) z_min = std::min(z_min, q.y());
    for (const auto& q : lower_.profile)
        if (q.y() <= z_min + 1e-9) r = std::max(r, q.x());
    return r;
}

}  // namespace hotgauge::core
