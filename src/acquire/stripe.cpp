// Laser-line extraction (docs/acquisition.md). The image is read once, row by row, into the
// per-column maxima of groups of rows: contiguous loads the compiler vectorises, where walking
// down a column would touch a new cache line for every pixel. Only the few rows around each
// column's peak (and those of a second peak that may matter) are then read column-wise.
#include "hotgauge/acquire/stripe.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <string>

namespace hotgauge::acquire {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr int kGroupRows = 16;  // rows per group of the per-column group maxima

// Linear background through the means of the two bands just outside the window [m − w, m + w]:
// hot steel glows, and its glow changes along the column, so a constant or global level would
// either bias the centre or hide the stripe (algorithm-notes "Laser stripe centre").
struct Background {
    double level = 0.0;  // at row `at`
    double slope = 0.0;  // counts per row
    double at = 0.0;
    double operator()(double row) const { return level + slope * (row - at); }
};

template <class Pixel>
Background local_background(const Pixel* column, std::ptrdiff_t stride, int height, int m,
                            const StripeConfig& config) {
    const int w = config.window_half_width, band = config.background_band;
    struct Band {
        bool present = false;
        double mean = 0.0, centre = 0.0;
    };
    const auto band_mean = [&](int r0, int r1) {
        r0 = std::max(r0, 0);
        r1 = std::min(r1, height - 1);
        Band b;
        if (r0 > r1) return b;
        double sum = 0.0;
        for (int r = r0; r <= r1; ++r) sum += column[r * stride];
        b.present = true;
        b.mean = sum / (r1 - r0 + 1);
        b.centre = 0.5 * (r0 + r1);
        return b;
    };
    const Band left = band_mean(m - w - band, m - w - 1),
               right = band_mean(m + w + 1, m + w + band);
    if (left.present && right.present)
        return {left.mean, (right.mean - left.mean) / (right.centre - left.centre), left.centre};
    if (left.present) return {left.mean, 0.0, 0.0};
    if (right.present) return {right.mean, 0.0, 0.0};
    return {};
}

// Rows a, b, c, d (repeats allowed: max is idempotent) into their row group's per-column maxima,
// `init`: the group's first rows (group_best is not read). Fixed-size blocks with unaliased
// pointers and no data-dependent select: the form GCC vectorises at -O2 in the pixels' own lane
// width (16 Mono8 or 8 Mono16 columns per 16-byte instruction), four rows per load and store of
// the maxima.
template <class Pixel, std::size_t kBlock, bool kInit>
void group_max_block(const Pixel* __restrict a, const Pixel* __restrict b,
                     const Pixel* __restrict c, const Pixel* __restrict d,
                     Pixel* __restrict group_best, std::size_t count) {
    const std::size_t n = kBlock > 0 ? kBlock : count;
    for (std::size_t i = 0; i < n; ++i) {
        const Pixel m = std::max(std::max(a[i], b[i]), std::max(c[i], d[i]));
        group_best[i] = kInit ? m : std::max(group_best[i], m);
    }
}

template <class Pixel, bool kInit>
void rows_into_group(const Pixel* a, const Pixel* b, const Pixel* c, const Pixel* d,
                     Pixel* group_best, std::size_t n) {
    constexpr std::size_t kBlock = 64;
    std::size_t i = 0;
    for (; i + kBlock <= n; i += kBlock)
        group_max_block<Pixel, kBlock, kInit>(a + i, b + i, c + i, d + i, group_best + i, 0);
    group_max_block<Pixel, 0, kInit>(a + i, b + i, c + i, d + i, group_best + i, n - i);
}

// One row group's maxima into the per-column maxima (value, first group reaching it).
template <class Pixel, std::size_t kBlock>
void peak_group_block(const Pixel* __restrict group_best, Pixel* __restrict best,
                      std::uint16_t* __restrict best_group, std::uint16_t g, std::size_t count) {
    const std::size_t n = kBlock > 0 ? kBlock : count;
    for (std::size_t c = 0; c < n; ++c) {
        const bool up = group_best[c] > best[c];
        best[c] = up ? group_best[c] : best[c];
        best_group[c] = up ? g : best_group[c];
    }
}

// Per column, the highest pixel farther than `separation` rows from the column's peak (the first
// row reaching it): the candidate reflection. Equal to a row-by-row scan of every column, at a
// fraction of the cost: row groups wholly outside a column's excluded rows contribute their
// maxima (a vectorised loop over columns per group, for all columns), the at most two groups the
// excluded rows cut are read pixel by pixel, and the winning group is searched for its row only
// if the candidate may be a double peak (second_peak, per column when the test is reached).
template <class Pixel, std::size_t kBlock>
void group_candidates_block(const Pixel* __restrict group_best, const std::uint16_t* __restrict lo,
                            const std::uint16_t* __restrict hi, Pixel* __restrict best,
                            std::uint16_t* __restrict best_group, std::uint16_t g,
                            std::uint16_t first_row, std::uint16_t last_row, std::size_t count) {
    const std::size_t n = kBlock > 0 ? kBlock : count;
    for (std::size_t c = 0; c < n; ++c) {
        const bool up = ((last_row < lo[c]) | (first_row > hi[c])) & (group_best[c] > best[c]);
        best[c] = up ? group_best[c] : best[c];
        best_group[c] = up ? g : best_group[c];
    }
}

// The first row of row group g of a column holding `value` (the group's maximum: the loop ends
// in the group).
template <class Pixel>
int first_row_at(const Pixel* column, std::ptrdiff_t stride, int g, int value) {
    int row = g * kGroupRows;
    while (column[row * stride] != value) ++row;
    return row;
}

template <class Pixel>
struct GroupCandidates {
    std::vector<std::uint16_t> lo, hi;  // excluded rows [lo, hi]
    std::vector<Pixel> best;            // the highest maximum of the groups outside them
    std::vector<std::uint16_t> best_group;
};

template <class Pixel>
GroupCandidates<Pixel> group_candidates(int height, const std::vector<Pixel>& group_max,
                                        const std::vector<std::uint16_t>& peak_row,
                                        int separation) {
    const std::size_t n = peak_row.size();
    GroupCandidates<Pixel> out{std::vector<std::uint16_t>(n), std::vector<std::uint16_t>(n),
                               std::vector<Pixel>(n, Pixel{0}), std::vector<std::uint16_t>(n, 0)};
    for (std::size_t c = 0; c < n; ++c) {
        out.lo[c] = static_cast<std::uint16_t>(std::max(peak_row[c] - separation, 0));
        out.hi[c] = static_cast<std::uint16_t>(std::min(peak_row[c] + separation, height - 1));
    }
    constexpr std::size_t kBlock = 64;
    for (int g = 0; g * kGroupRows < height; ++g) {
        const auto first = static_cast<std::uint16_t>(g * kGroupRows);
        const auto last = static_cast<std::uint16_t>(std::min((g + 1) * kGroupRows, height) - 1);
        const Pixel* gm = group_max.data() + static_cast<std::size_t>(g) * n;
        const auto gg = static_cast<std::uint16_t>(g);
        std::size_t c = 0;
        for (; c + kBlock <= n; c += kBlock)
            group_candidates_block<Pixel, kBlock>(gm + c, out.lo.data() + c, out.hi.data() + c,
                                                  out.best.data() + c, out.best_group.data() + c,
                                                  gg, first, last, 0);
        group_candidates_block<Pixel, 0>(gm + c, out.lo.data() + c, out.hi.data() + c,
                                         out.best.data() + c, out.best_group.data() + c, gg, first,
                                         last, n - c);
    }
    return out;
}

struct SecondPeak {
    int value = 0;  // 0: no candidate
    int row = -1;   // −1 with value > 0: the first row of `group` holding value, not searched yet
    int group = 0;
};

// Column c's candidate: the winning group's, unless a row of the groups the excluded rows cut
// beats it. Those rows are never in the winning group (it lies wholly outside [lo, hi]), so
// "lower row" on a tie needs only the group's first row, not the searched row.
template <class Pixel>
SecondPeak second_peak(const Pixel* column, std::ptrdiff_t stride, int height,
                       const GroupCandidates<Pixel>& candidates, std::size_t c) {
    SecondPeak out{candidates.best[c], -1, candidates.best_group[c]};
    int key = out.value > 0 ? out.group * kGroupRows : -1;  // orders rows as the candidate's row
    // Ties: the lower row. Selects, not branches: which pixel wins is noise.
    const auto consider = [&](int r0, int r1) {
        for (int r = r0; r <= r1; ++r) {
            const int v = column[r * stride];
            const bool take = (v > out.value) | ((v == out.value) & (v > 0) & (r < key));
            out.value = take ? v : out.value;
            out.row = take ? r : out.row;
            key = take ? r : key;
        }
    };
    const int lo = candidates.lo[c], hi = candidates.hi[c];
    consider(lo / kGroupRows * kGroupRows, lo - 1);
    consider(hi + 1, std::min((hi / kGroupRows + 1) * kGroupRows, height) - 1);
    return out;
}

// Mean of (value − background) over rows m − 1 … m + 1 (those inside the image).
template <class Pixel>
double peak_contrast(const Pixel* column, std::ptrdiff_t stride, int height, int m,
                     const Background& background) {
    const int r0 = std::max(m - 1, 0), r1 = std::min(m + 1, height - 1);
    double sum = 0.0;
    for (int r = r0; r <= r1; ++r) sum += column[r * stride] - background(r);
    return sum / (r1 - r0 + 1);
}

// An upper bound of the candidate's peak_contrast from the group maxima alone (one value per
// group, written by the first pass, still in cache), without reading the column's pixels at
// rows far from the peak. The contrast is the mean of (value − background) over rows m2 − 1 …
// m2 + 1; the background there is ≥ 0 (a band mean, or the line through two band means
// evaluated strictly between the bands' centres), and rounding is monotone, so the contrast
// never exceeds the highest of those pixels, nor the maxima of their groups (m2 not searched
// yet: anywhere in its group). A bound below the threshold decides the test exactly as the
// contrast would.
template <class Pixel>
int contrast_bound(const SecondPeak& second, const Pixel* group_max_column, std::size_t n,
                   int height) {
    const int first = second.row >= 0 ? second.row : second.group * kGroupRows;
    const int last = second.row >= 0 ? second.row : std::min(first + kGroupRows, height) - 1;
    const int g0 = std::max(first - 1, 0) / kGroupRows;
    const int g1 = std::min(last + 1, height - 1) / kGroupRows;
    int bound = 0;
    for (int g = g0; g <= g1; ++g)
        bound = std::max<int>(bound, group_max_column[static_cast<std::size_t>(g) * n]);
    return bound;
}

// One pass over the image, row by row: the maximum of every group of kGroupRows rows per column
// (n_groups rows of n maxima; also for the second peak, below).
template <class Pixel>
std::vector<Pixel> group_maxima(const Pixel* pixels, std::size_t n, int height,
                                std::ptrdiff_t stride, int n_groups) {
    std::vector<Pixel> group_max(static_cast<std::size_t>(n_groups) * n);
    for (int g = 0; g < n_groups; ++g) {
        const int first = g * kGroupRows, last = std::min(first + kGroupRows, height) - 1;
        Pixel* gm = group_max.data() + static_cast<std::size_t>(g) * n;
        const auto row = [&](int r) { return pixels + std::min(r, last) * stride; };
        rows_into_group<Pixel, true>(row(first), row(first + 1), row(first + 2), row(first + 3), gm,
                                     n);
        for (int r = first + 4; r <= last; r += 4)
            rows_into_group<Pixel, false>(row(r), row(r + 1), row(r + 2), row(r + 3), gm, n);
    }
    return group_max;
}

template <class Pixel>
struct ColumnPeaks {
    std::vector<Pixel> peak;              // per column, its highest pixel
    std::vector<std::uint16_t> peak_row;  // the first row reaching it
};

// Per column the maximum and the first group reaching it (a pass over 1/kGroupRows of the
// image), and in that group the first row reaching it (at most kGroupRows pixels per column;
// neighbouring columns' peaks share cache lines).
template <class Pixel>
ColumnPeaks<Pixel> column_peaks(const Pixel* pixels, std::ptrdiff_t stride,
                                const std::vector<Pixel>& group_max, std::size_t n, int n_groups) {
    ColumnPeaks<Pixel> out{std::vector<Pixel>(n, Pixel{0}), std::vector<std::uint16_t>(n, 0)};
    auto& peak = out.peak;
    auto& peak_row = out.peak_row;  // the first group reaching the peak, then its row
    constexpr std::size_t kBlock = 64;
    for (int g = 0; g < n_groups; ++g) {
        const Pixel* gm = group_max.data() + static_cast<std::size_t>(g) * n;
        const auto gg = static_cast<std::uint16_t>(g);
        std::size_t c = 0;
        for (; c + kBlock <= n; c += kBlock)
            peak_group_block<Pixel, kBlock>(gm + c, peak.data() + c, peak_row.data() + c, gg, 0);
        peak_group_block<Pixel, 0>(gm + c, peak.data() + c, peak_row.data() + c, gg, n - c);
    }
    for (std::size_t c = 0; c < n; ++c)
        peak_row[c] =
            static_cast<std::uint16_t>(first_row_at(pixels + c, stride, peak_row[c], peak[c]));
    return out;
}

// Whether column c (peak at row m) has a second peak whose contrast reaches double_peak_ratio
// times its peak's. Both peaks' contrast as the mean over their 3 central rows, each against its
// own flanks: a glow gradient rising along the column is not a peak, a single noisy pixel hardly
// is, a reflection (a line, several pixels wide) is.
template <class Pixel>
bool double_peak(const Pixel* column, std::ptrdiff_t stride, int height, int m,
                 const Background& background, const GroupCandidates<Pixel>& candidates,
                 std::size_t c, const std::vector<Pixel>& group_max, std::size_t n,
                 const StripeConfig& config) {
    SecondPeak second = second_peak(column, stride, height, candidates, c);
    if (second.value > 0) {
        const double threshold =
            config.double_peak_ratio * peak_contrast(column, stride, height, m, background);
        // The candidate's rows are read only if its bound can reach the threshold.
        if (contrast_bound(second, group_max.data() + c, n, height) >= threshold) {
            if (second.row < 0)
                second.row = first_row_at(column, stride, second.group, second.value);
            const int m2 = second.row;
            const double contrast2 = peak_contrast(
                column, stride, height, m2, local_background(column, stride, height, m2, config));
            if (contrast2 >= threshold) return true;
        }
    }
    return false;
}

// The centre of gravity of (value − background) over the window rows r0 … r1, or with
// gaussian_refinement the log-parabola's vertex through the peak m and its neighbours.
template <class Pixel>
double stripe_centre(const Pixel* column, std::ptrdiff_t stride, int height, int m, int r0, int r1,
                     const Background& background, double contrast, const StripeConfig& config) {
    double sum = 0.0, sum_r = 0.0;
    for (int r = r0; r <= r1; ++r) {
        const double a = column[r * stride] - background(r);
        if (a > 0.0) {
            sum += a;
            sum_r += a * r;
        }
    }
    double centre = sum_r / sum;  // sum ≥ contrast ≥ min_peak > 0
    if (config.gaussian_refinement && m > 0 && m < height - 1) {
        // Log-parabola through the peak and its neighbours: exact for a Gaussian profile,
        // free of the centre of gravity's pull towards the window's middle.
        const double a = column[(m - 1) * stride] - background(m - 1);
        const double b = contrast;
        const double d = column[(m + 1) * stride] - background(m + 1);
        if (a > 0.0 && d > 0.0) {
            const double la = std::log(a), lb = std::log(b), ld = std::log(d);
            const double curvature = la - 2.0 * lb + ld;
            if (curvature < 0.0) {
                const double delta = 0.5 * (la - ld) / curvature;
                if (std::abs(delta) <= 1.0) centre = m + delta;
            }
        }
    }
    return centre;
}

template <class Pixel>
std::vector<StripePoint> extract(const Pixel* pixels, int width, int height, std::ptrdiff_t stride,
                                 const StripeConfig& config) {
    assert(check_stripe_config(config).ok());
    assert(width >= 0 && height >= 0);
    // Rows are kept as uint16, the lane width of Mono16 pixels.
    assert(height < 65536);
    std::vector<StripePoint> out(static_cast<std::size_t>(width),
                                 StripePoint{kNaN, 0.0F, StripeStatus::kNoReturn});
    if (width == 0 || height == 0) return out;
    const auto n = static_cast<std::size_t>(width);

    // One pass over the image for the group maxima; from them each column's peak and its row.
    const int n_groups = (height + kGroupRows - 1) / kGroupRows;
    const std::vector<Pixel> group_max = group_maxima(pixels, n, height, stride, n_groups);
    const auto [peak, peak_row] = column_peaks(pixels, stride, group_max, n, n_groups);

    const bool double_peaks = config.double_peak_ratio > 0.0;
    const GroupCandidates<Pixel> candidates =
        double_peaks
            ? group_candidates(height, group_max, peak_row, config.double_peak_min_separation_px)
            : GroupCandidates<Pixel>{};

    // Per column: classify, then the centre of gravity of (value − background) in the window.
    const int w = config.window_half_width;
    const int saturation = config.saturation_level > 0 ? config.saturation_level : config.max_value;
    for (std::size_t c = 0; c < n; ++c) {
        StripePoint& point = out[c];
        if (peak[c] < config.min_peak) continue;  // kNoReturn
        const Pixel* column = pixels + c;
        const int m = peak_row[c];
        const Background background = local_background(column, stride, height, m, config);
        const double contrast = peak[c] - background(m);
        point.quality = static_cast<float>(std::clamp(contrast / config.max_value, 0.0, 1.0));

        const int r0 = std::max(m - w, 0), r1 = std::min(m + w, height - 1);
        bool saturated = false;
        for (int r = r0; r <= r1; ++r) saturated |= column[r * stride] >= saturation;
        if (saturated) {
            point.status = StripeStatus::kSaturated;
            continue;
        }
        if (contrast < config.min_peak) {
            point.status = StripeStatus::kDark;
            continue;
        }
        if (double_peaks && double_peak(column, stride, height, m, background, candidates, c,
                                        group_max, n, config)) {
            point.status = StripeStatus::kDoublePeak;
            continue;
        }
        const double centre =
            stripe_centre(column, stride, height, m, r0, r1, background, contrast, config);
        point.row = static_cast<float>(centre);
        point.status = StripeStatus::kOk;
    }
    return out;
}

}  // namespace

core::Result<void> check_stripe_config(const StripeConfig& config) {
    const auto fail = [](const std::string& what) { return core::make_error(what); };
    bool bits_ok = false;
    for (int bits = 8; bits <= 16; ++bits) bits_ok |= config.max_value == (1 << bits) - 1;
    if (!bits_ok)
        return fail(
            "max_value must be 2^bits - 1 with 8 <= bits <= 16 (255, 1023, 4095, 65535, "
            "...), got " +
            std::to_string(config.max_value));
    if (config.saturation_level < 0 || config.saturation_level > config.max_value)
        return fail("saturation_level must be in [1, max_value] (0: max_value), got " +
                    std::to_string(config.saturation_level));
    if (!(config.min_peak > 0.0 && config.min_peak < config.max_value))
        return fail("min_peak must be in (0, max_value), got " + std::to_string(config.min_peak));
    if (config.window_half_width < 1 || config.window_half_width > 64)
        return fail("window_half_width must be in [1, 64] px, got " +
                    std::to_string(config.window_half_width));
    if (config.background_band < 1 || config.background_band > 64)
        return fail("background_band must be in [1, 64] px, got " +
                    std::to_string(config.background_band));
    if (!(config.double_peak_ratio >= 0.0 && config.double_peak_ratio <= 1.0))
        return fail("double_peak_ratio must be in [0, 1] (0: off), got " +
                    std::to_string(config.double_peak_ratio));
    if (config.double_peak_min_separation_px <= config.window_half_width ||
        config.double_peak_min_separation_px > 1000)
        return fail("double_peak_min_separation_px must exceed window_half_width (" +
                    std::to_string(config.window_half_width) + ") and be at most 1000, got " +
                    std::to_string(config.double_peak_min_separation_px));
    return {};
}

std::vector<StripePoint> extract_stripe(const std::uint16_t* pixels, int width, int height,
                                        std::ptrdiff_t stride_pixels, const StripeConfig& config) {
    return extract(pixels, width, height, stride_pixels, config);
}

std::vector<StripePoint> extract_stripe(const std::uint8_t* pixels, int width, int height,
                                        std::ptrdiff_t stride_pixels, const StripeConfig& config) {
    assert(config.max_value <= 255);
    return extract(pixels, width, height, stride_pixels, config);
}

core::Result<void> check_peak_format(const PeakFormat& format) {
    if (format.fractional_bits < 0 || format.fractional_bits > 15)
        return core::make_error("fractional_bits must be in [0, 15], got " +
                                std::to_string(format.fractional_bits));
    if (format.profiles_per_frame < 1 || format.profiles_per_frame > 65535)
        return core::make_error("profiles_per_frame must be in [1, 65535], got " +
                                std::to_string(format.profiles_per_frame));
    if (format.intensity && (format.intensity_max_value < 1 || format.intensity_max_value > 65535))
        return core::make_error("intensity_max_value must be in [1, 65535], got " +
                                std::to_string(format.intensity_max_value));
    return {};
}

std::vector<StripePoint> decode_peaks(const std::uint16_t* data, int width,
                                      const PeakFormat& format) {
    std::vector<StripePoint> out;
    decode_peaks(data, width, format, out);
    return out;
}

void decode_peaks(const std::uint16_t* data, int width, const PeakFormat& format,
                  std::vector<StripePoint>& out) {
    assert(check_peak_format(format).ok());
    assert(width >= 0);
    const auto w = static_cast<std::ptrdiff_t>(width);
    // value · 2^−bits is exact in float: 16 significant bits, a power-of-two scale.
    const float scale = std::ldexp(1.0F, -format.fractional_bits);
    const float inv_intensity_max = 1.0F / static_cast<float>(format.intensity_max_value);
    out.resize(static_cast<std::size_t>(format.profiles_per_frame * w));
    for (int k = 0; k < format.profiles_per_frame; ++k) {
        const std::uint16_t* peak = data + k * format.rows_per_profile() * w;
        const std::uint16_t* second = format.second_peak ? peak + w : nullptr;
        const std::uint16_t* intensity =
            format.intensity ? peak + (format.second_peak ? 2 : 1) * w : nullptr;
        StripePoint* profile = out.data() + k * w;
        for (std::ptrdiff_t i = 0; i < w; ++i) {
            const float quality =
                intensity ? std::min(1.0F, static_cast<float>(intensity[i]) * inv_intensity_max)
                          : 1.0F;
            if (peak[i] == 0)
                profile[i] = {kNaN, 0.0F, StripeStatus::kNoReturn};
            else if (second && second[i] != 0)
                profile[i] = {kNaN, quality, StripeStatus::kDoublePeak};
            else
                profile[i] = {static_cast<float>(peak[i]) * scale, quality, StripeStatus::kOk};
        }
    }
}

}  // namespace hotgauge::acquire
