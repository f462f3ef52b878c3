// Face preparation: the part-frame samples near the part, bucketed by z, and the per-column ray
// model x = a_i + b_i·z (docs/measurement.md, "Preparation" and "Corrupt samples").
#include "frame.hpp"

namespace hotgauge::measure::detail {
namespace {

// A column's slope is fitted from at least this many samples spread over at least this depth
// variance (mm²); others take their neighbours' slope (not measured).
constexpr int kMinSlopeSamples = 10;
constexpr double kMinSlopeVarZMm2 = 1.0;

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
        // Too little depth spread to see the slope:
        if (c.s < kMinSlopeSamples || var_z < kMinSlopeVarZMm2) continue;
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

// The columns of a profile from its first sample with a return to after its last (a side face's
// profile sees the part in a fifth of its width): the second pass visits only these.
struct ColumnSpan {
    std::int64_t first = 0, end = 0;
};

// A corrupt sample off its column's ray (which a calibrated sensor cannot produce) would tilt
// that column's line: columns with a sample farther than kRayToleranceMm from their line are
// fitted again from the samples near a robust (median) line.
void refit_off_ray_columns(const core::FaceScan& f, const std::vector<ColumnSpan>& spans,
                           std::vector<ColumnSums>& sums, std::vector<double>& a,
                           std::vector<double>& b) {
    constexpr double kRayToleranceMm = 0.5;
    const std::int64_t n = f.n_profiles(), w = f.width;
    std::vector<std::uint8_t> bad(static_cast<std::size_t>(w), 0);
    bool any = false;
    for (std::int64_t k = 0; k < n; ++k) {
        const float* row = f.profiles_mm.data() + k * w * 2;  // (x, z) per column
        for (std::int64_t i = spans[k].first; i < spans[k].end; ++i) {
            const double x = row[2 * i], z = row[2 * i + 1];
            if (!std::isfinite(x) || !std::isfinite(z) || std::isnan(b[i])) continue;
            if (std::abs(x - a[i] - b[i] * z) > kRayToleranceMm) {
                bad[i] = 1;
                any = true;
            }
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
    std::vector<ColumnSums> columns(static_cast<std::size_t>(fr.w));
    std::vector<ColumnSpan> spans(static_cast<std::size_t>(fr.n));
    const double r2_max = r_max * r_max;
    for (std::int64_t k = 0; k < fr.n; ++k) {
        Eigen::Vector3d t =
            f.T_world_camera.translation() + f.profile_positions_mm[k] * f.scan_direction;
        if (u && static_cast<std::int64_t>(u->size()) == fr.n) t += (*u)[k];
        fr.origin[k] = T_part_world * t;
        const float* row = f.profiles_mm.data() + k * fr.w * 2;  // (x, z) per column
        const bool left_out = fr.left_out(k);
        // Local copies: the stores below could alias fr's members, which were then loaded again
        // for every sample.
        const Eigen::Matrix3d M = fr.M;
        const Eigen::Vector3d origin = fr.origin[k];
        ColumnSpan span;
        for (std::int64_t i = 0; i < fr.w; ++i) {
            const float x = row[2 * i], z = row[2 * i + 1];
            if (!std::isfinite(x) || !std::isfinite(z)) continue;
            if (span.end == 0) span.first = i;
            span.end = i + 1;
            columns[i].add(x, z);  // a column's ray does not depend on the compensation
            if (left_out) continue;
            const Eigen::Vector3d p = M * Eigen::Vector3d(x, 0.0, z) + origin;
            const double r2 = p.x() * p.x() + p.y() * p.y();
            if (!(r2 <= r2_max && p.z() >= z_lo && p.z() <= z_hi)) continue;  // NaN-safe
            near.push_back({k * fr.w + i, p.cast<float>(), static_cast<float>(std::sqrt(r2))});
        }
        spans[k] = span;
    }
    fit_columns(columns, fr.col_a, fr.col_b);
    refit_off_ray_columns(f, spans, columns, fr.col_a, fr.col_b);
    bucket_by_z(fr, near, z_lo, z_hi);
    return fr;
}

}  // namespace hotgauge::measure::detail
