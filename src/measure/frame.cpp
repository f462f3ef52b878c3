// Face preparation: the part-frame samples near the part, bucketed by z, and the per-column ray
// model x = a_i + b_i·z (docs/measurement.md, "Preparation" and "Corrupt samples").
#include "frame.hpp"

#include <bit>

namespace hotgauge::measure::detail {
namespace {

// A column's slope is fitted from at least this many samples spread over at least this depth
// variance (mm²); others take their neighbours' slope (not measured).
constexpr int kMinSlopeSamples = 10;
constexpr double kMinSlopeVarZMm2 = 1.0;

// A sample with a return: both coordinates finite. Written without branches for the vector loops
// (a NaN compares false).
inline bool is_return(float x, float z) {
    constexpr float kMax = std::numeric_limits<float>::max();
    return (std::abs(x) <= kMax) & (std::abs(z) <= kMax);
}
// Column i of a profile row (x, z per column).
inline bool has_return(const float* row, std::int64_t i) {
    return is_return(row[2 * i], row[2 * i + 1]);
}

// v with its bits and-ed with mask: v itself (mask all ones) or +0 (mask zero).
inline float masked(float v, std::uint32_t mask) {
    return std::bit_cast<float>(std::bit_cast<std::uint32_t>(v) & mask);
}

// Per-column sums of the camera-frame samples, for the least-squares ray line x = a + b·z of
// each column. A sensor computes (x, z) from (column, row) through its calibration, so every
// sample of a column lies on that column's ray whatever it hit: one pass, no outliers to reject.
// One array per sum, so that a profile's columns are added in one vector loop.
struct ColumnSums {
    std::vector<double> s, sz, sx, szz, szx;
    explicit ColumnSums(std::int64_t w)
        : s(w, 0.0), sz(w, 0.0), sx(w, 0.0), szz(w, 0.0), szx(w, 0.0) {}
    void add(std::int64_t i, double x, double z) {
        s[i] += 1;
        sz[i] += z;
        sx[i] += x;
        szz[i] += z * z;
        szx[i] += z * x;
    }
    void clear(std::int64_t i) { s[i] = sz[i] = sx[i] = szz[i] = szx[i] = 0.0; }
    // Adds the samples of one profile's columns [first, end) that have a return. A sample
    // without one adds zeros, which leave every sum's bits as they were (the sums start at +0).
    void add_profile(const float* row, std::int64_t first, std::int64_t end) {
        double *s_ = s.data(), *sz_ = sz.data(), *sx_ = sx.data(), *szz_ = szz.data(),
               *szx_ = szx.data();
#pragma omp simd
        for (std::int64_t i = first; i < end; ++i) {
            const float xf = row[2 * i], zf = row[2 * i + 1];
            // All bits kept with a return, +0 without (a select that GCC vectorizes).
            const std::uint32_t keep = 0u - static_cast<std::uint32_t>(is_return(xf, zf));
            const double x = masked(xf, keep), z = masked(zf, keep);
            s_[i] += masked(1.0f, keep);
            sz_[i] += z;
            sx_[i] += x;
            szz_[i] += z * z;
            szx_[i] += z * x;
        }
    }
};

void fit_columns(const ColumnSums& c, std::vector<double>& a, std::vector<double>& b) {
    const auto w = static_cast<std::int64_t>(c.s.size());
    a.assign(w, kNaN);
    b.assign(w, kNaN);
    std::vector<double> mean_x(w, kNaN), mean_z(w, kNaN);
    for (std::int64_t i = 0; i < w; ++i) {
        if (c.s[i] < 1) continue;
        mean_x[i] = c.sx[i] / c.s[i];
        mean_z[i] = c.sz[i] / c.s[i];
        const double var_z = c.szz[i] / c.s[i] - mean_z[i] * mean_z[i];
        // Too little depth spread to see the slope:
        if (c.s[i] < kMinSlopeSamples || var_z < kMinSlopeVarZMm2) continue;
        b[i] = (c.szx[i] / c.s[i] - mean_x[i] * mean_z[i]) / var_z;
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

// The columns of a profile from its first sample with a return to after its last (a side face's
// profile sees the part in a fifth of its width): the loops over a profile visit only these.
struct ColumnSpan {
    std::int64_t first = 0, end = 0;
};

// A corrupt sample off its column's ray (which a calibrated sensor cannot produce) would tilt
// that column's line: columns with a sample farther than kRayToleranceMm from their line are
// fitted again from the samples near a robust (median) line.
void refit_off_ray_columns(const core::FaceScan& f, const std::vector<ColumnSpan>& spans,
                           ColumnSums& sums, std::vector<double>& a, std::vector<double>& b) {
    constexpr double kRayToleranceMm = 0.5;
    const std::int64_t n = f.n_profiles(), w = f.width;
    // Per column, how many samples lie off the ray (only whether any does is used; a count, so
    // that the loop below vectorizes).
    std::vector<std::int32_t> off(static_cast<std::size_t>(w), 0);
    const double *a_ = a.data(), *b_ = b.data();
    std::int32_t* off_ = off.data();
    for (std::int64_t k = 0; k < n; ++k) {
        const float* row = f.profiles_mm.data() + k * w * 2;  // (x, z) per column
        // Without a return, or on a column without a slope (NaN), the test is false.
#pragma omp simd
        for (std::int64_t i = spans[k].first; i < spans[k].end; ++i) {
            const float xf = row[2 * i], zf = row[2 * i + 1];
            const double x = xf, z = zf;
            off_[i] += is_return(xf, zf) & (std::abs(x - a_[i] - b_[i] * z) > kRayToleranceMm);
        }
    }
    const bool any = std::any_of(off.begin(), off.end(), [](std::int32_t v) { return v != 0; });
    if (!any) return;
    for (std::int64_t i = 0; i < w; ++i) {
        if (!off[i]) continue;
        std::vector<double> xs, zs, ratio, icpt;
        for (std::int64_t k = 0; k < n; ++k) {
            const double x = f.x(k, i), z = f.z(k, i);
            if (std::isfinite(x) && std::isfinite(z) && z != 0.0) {
                xs.push_back(x);
                zs.push_back(z);
                ratio.push_back(x / z);
            }
        }
        sums.clear(i);
        if (xs.empty()) continue;
        std::nth_element(ratio.begin(), ratio.begin() + ratio.size() / 2, ratio.end());
        const double b0 = ratio[ratio.size() / 2];
        for (std::size_t j = 0; j < xs.size(); ++j) icpt.push_back(xs[j] - b0 * zs[j]);
        std::nth_element(icpt.begin(), icpt.begin() + icpt.size() / 2, icpt.end());
        const double a0 = icpt[icpt.size() / 2];
        for (std::size_t j = 0; j < xs.size(); ++j)
            if (std::abs(xs[j] - a0 - b0 * zs[j]) <= kRayToleranceMm) sums.add(i, xs[j], zs[j]);
    }
    fit_columns(sums, a, b);
}

// Whether columns [i, i + kSpanBlock) hold a return: one vector test per block, for the long
// runs without a return on either side of a side face's part.
constexpr std::int64_t kSpanBlock = 16;
bool block_has_return(const float* row, std::int64_t i) {
    std::uint32_t any = 0;
#pragma omp simd reduction(| : any)
    for (std::int64_t j = i; j < i + kSpanBlock; ++j) any |= has_return(row, j);
    return any != 0;
}

ColumnSpan row_span(const float* row, std::int64_t w) {
    ColumnSpan span;
    while (span.first + kSpanBlock <= w && !block_has_return(row, span.first))
        span.first += kSpanBlock;
    while (span.first < w && !has_return(row, span.first)) ++span.first;
    if (span.first == w) return {};
    span.end = w;
    while (span.end - kSpanBlock >= span.first && !block_has_return(row, span.end - kSpanBlock))
        span.end -= kSpanBlock;
    while (!has_return(row, span.end - 1)) --span.end;
    return span;
}

// One profile's samples in the part frame, column by column, and which of them lie inside the
// part's bounding cylinder (`keep`). One vector loop: a sample without a return computes NaN or
// ±inf, and is_return leaves it out.
struct RowPoints {
    std::vector<double> x, y, z;
    std::vector<double> r2;  // squared distance from the part axis (its root only where kept)
    std::vector<std::uint8_t> keep;
    explicit RowPoints(std::int64_t w) : x(w), y(w), z(w), r2(w), keep(w) {}

    // p = M·(x, 0, z) + origin, as `M * Vector3d(x, 0, z) + origin` computed it before, to the
    // bit: M's middle column times 0 is an exact ±0 (M is finite), so Eigen's grouping of the
    // three products (its row 2 adds the last two first) gives the same sum, signed zeros
    // included. Do not drop the `* 0.0` terms: that changes the sign of some zeros. (With FMA
    // enabled, -march=haswell and up, Eigen fuses its products and the bits would differ.)
    void transform(const float* row, ColumnSpan span, const Eigen::Matrix3d& M,
                   const Eigen::Vector3d& o, double r_max, double z_lo, double z_hi) {
        const double r2_max = r_max * r_max;
        const double m00 = M(0, 0), m01 = M(0, 1), m02 = M(0, 2), m10 = M(1, 0), m11 = M(1, 1),
                     m12 = M(1, 2), m20 = M(2, 0), m21 = M(2, 1), m22 = M(2, 2);
        const double ox = o.x(), oy = o.y(), oz = o.z();
        double *x_ = x.data(), *y_ = y.data(), *z_ = z.data();
        double* r2_ = r2.data();
        std::uint8_t* keep_ = keep.data();
#pragma omp simd
        for (std::int64_t i = span.first; i < span.end; ++i) {
            const float xf = row[2 * i], zf = row[2 * i + 1];
            const double sx = xf, sz = zf;
            const double px = m00 * sx + m01 * 0.0 + m02 * sz + ox;
            const double py = m10 * sx + m11 * 0.0 + m12 * sz + oy;
            const double pz = m20 * sx + m21 * 0.0 + m22 * sz + oz;
            const double d2 = px * px + py * py;
            r2_[i] = d2;
            x_[i] = px;  // to float where kept: a corrupt sample may not fit a float
            y_[i] = py;
            z_[i] = pz;
            keep_[i] = is_return(xf, zf) & (d2 <= r2_max) & (pz >= z_lo) & (pz <= z_hi);
        }
    }
};

// The near samples in scan order, in blocks of 1.5 MB: as one vector, a top face's 50 MB were
// mapped from the kernel, zeroed and given back for every face (10-20 ms of system time a part in
// `hotgauge remeasure`); blocks this size come from the allocator's heap and are reused.
class NearBlocks {
  public:
    void push_back(const FaceFrame::Near& s) {
        if (blocks_.empty() || blocks_.back().size() == kBlock) {
            blocks_.emplace_back();
            blocks_.back().reserve(kBlock);
        }
        blocks_.back().push_back(s);
        ++size_;
    }
    std::size_t size() const { return size_; }
    template <class F>
    void for_each(F&& f) const {
        for (const auto& b : blocks_)
            for (const auto& s : b) f(s);
    }

  private:
    static constexpr std::size_t kBlock = 1 << 16;
    std::vector<std::vector<FaceFrame::Near>> blocks_;
    std::size_t size_ = 0;
};

// Counting sort of the near-part samples by z bucket.
void bucket_by_z(FaceFrame& fr, const NearBlocks& near, double z_lo, double z_hi) {
    const auto nb = static_cast<std::int64_t>((z_hi - z_lo) / FaceFrame::kBucketMm) + 1;
    fr.z0 = z_lo;
    auto index = [&](float z) {
        return std::clamp<std::int64_t>(
            static_cast<std::int64_t>((z - z_lo) / FaceFrame::kBucketMm), 0, nb - 1);
    };
    fr.bucket.assign(static_cast<std::size_t>(nb + 1), 0);
    near.for_each([&](const FaceFrame::Near& s) { ++fr.bucket[index(s.p.z()) + 1]; });
    for (std::int64_t b = 0; b < nb; ++b) fr.bucket[b + 1] += fr.bucket[b];
    fr.near.resize(near.size());
    std::vector<std::int64_t> fill(fr.bucket.begin(), fr.bucket.end() - 1);
    near.for_each([&](const FaceFrame::Near& s) { fr.near[fill[index(s.p.z())]++] = s; });
}

}  // namespace

FaceFrame make_frame(const core::FaceScan& f, const Eigen::Isometry3d& T_part_world,
                     const std::vector<Eigen::Vector3d>* u,
                     const std::vector<core::UntrustedProfiles>* untrusted, double r_max,
                     double z_lo, double z_hi) {
    FaceFrame fr;
    fr.scan = &f;
    fr.n = f.n_profiles();
    fr.w = f.width;
    if (untrusted && !untrusted->empty()) {
        fr.untrusted.assign(static_cast<std::size_t>(fr.n), 0);
        for (const auto& run : *untrusted)
            for (std::int64_t k = std::max<std::int64_t>(run.first, 0);
                 k <= std::min(run.last, fr.n - 1); ++k)
                fr.untrusted[static_cast<std::size_t>(k)] = 1;
    }
    fr.M = T_part_world.linear() * f.T_world_camera.linear();
    fr.view = fr.M.col(2);
    fr.origin.resize(fr.n);
    NearBlocks near;
    ColumnSums columns(fr.w);
    std::vector<ColumnSpan> spans(static_cast<std::size_t>(fr.n));
    RowPoints points(fr.w);
    for (std::int64_t k = 0; k < fr.n; ++k) {
        Eigen::Vector3d t =
            f.T_world_camera.translation() + f.profile_positions_mm[k] * f.scan_direction;
        if (u && static_cast<std::int64_t>(u->size()) == fr.n) t += (*u)[k];
        fr.origin[k] = T_part_world * t;
        const float* row = f.profiles_mm.data() + k * fr.w * 2;  // (x, z) per column
        const ColumnSpan span = row_span(row, fr.w);
        spans[k] = span;
        columns.add_profile(row, span.first, span.end);  // the ray ignores the compensation
        if (fr.left_out(k)) continue;
        points.transform(row, span, fr.M, fr.origin[k], r_max, z_lo, z_hi);
        for (std::int64_t i = span.first; i < span.end; ++i)
            if (points.keep[i])
                near.push_back(
                    {k * fr.w + i,
                     Eigen::Vector3d(points.x[i], points.y[i], points.z[i]).cast<float>(),
                     static_cast<float>(std::sqrt(points.r2[i]))});
    }
    fit_columns(columns, fr.col_a, fr.col_b);
    refit_off_ray_columns(f, spans, columns, fr.col_a, fr.col_b);
    bucket_by_z(fr, near, z_lo, z_hi);
    return fr;
}

}  // namespace hotgauge::measure::detail
