// Laser-line extraction (docs/acquisition.md). The image is read once, row by row, into
// per-column running maxima: contiguous loads the compiler vectorises, where walking down a
// column would touch a new cache line for every pixel. Only the few rows around each column's
// peaks are then read column-wise.
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

// One image row into the per-column running maxima (value, first row reaching it) and the
// current row group's maxima. Fixed-size blocks with unaliased pointers: the form GCC vectorises at
// -O2 (8 Mono16 columns per 16-byte instruction).
template <class Pixel, std::size_t kBlock>
void running_max_block(const Pixel* __restrict row, Pixel* __restrict best,
                       std::uint16_t* __restrict best_row, Pixel* __restrict group_best,
                       std::uint16_t r, std::size_t count) {
    const std::size_t n = kBlock > 0 ? kBlock : count;
    for (std::size_t c = 0; c < n; ++c) {
        const bool up = row[c] > best[c];
        best[c] = up ? row[c] : best[c];
        best_row[c] = up ? r : best_row[c];
        group_best[c] = std::max(group_best[c], row[c]);
    }
}

template <class Pixel>
void running_max(const Pixel* row, Pixel* best, std::uint16_t* best_row, Pixel* group_best,
                 std::uint16_t r, std::size_t n) {
    constexpr std::size_t kBlock = 64;
    std::size_t c = 0;
    for (; c + kBlock <= n; c += kBlock)
        running_max_block<Pixel, kBlock>(row + c, best + c, best_row + c, group_best + c, r, 0);
    running_max_block<Pixel, 0>(row + c, best + c, best_row + c, group_best + c, r, n - c);
}

// Per column, the highest pixel farther than `separation` rows from the column's peak (the first
// row reaching it): the candidate reflection. Equal to a row-by-row scan of every column, at a
// fraction of the cost: row groups wholly outside a column's excluded rows contribute their
// maxima (a vectorised loop over columns per group), the at most two groups the excluded rows cut
// are read pixel by pixel, and only the winning group is searched for its row.
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

struct SecondPeaks {
    std::vector<int> value, row;  // value 0: no candidate
};
template <class Pixel>
SecondPeaks second_peaks(const Pixel* pixels, std::ptrdiff_t stride, int height,
                         const std::vector<Pixel>& group_max,
                         const std::vector<std::uint16_t>& peak_row, int separation) {
    const std::size_t n = peak_row.size();
    std::vector<std::uint16_t> lo(n), hi(n);  // excluded rows [lo, hi]
    for (std::size_t c = 0; c < n; ++c) {
        lo[c] = static_cast<std::uint16_t>(std::max(peak_row[c] - separation, 0));
        hi[c] = static_cast<std::uint16_t>(std::min(peak_row[c] + separation, height - 1));
    }
    std::vector<Pixel> best(n, Pixel{0});
    std::vector<std::uint16_t> best_group(n, 0);
    constexpr std::size_t kBlock = 64;
    for (int g = 0; g * kGroupRows < height; ++g) {
        const auto first = static_cast<std::uint16_t>(g * kGroupRows);
        const auto last = static_cast<std::uint16_t>(std::min((g + 1) * kGroupRows, height) - 1);
        const Pixel* gm = group_max.data() + static_cast<std::size_t>(g) * n;
        const auto gg = static_cast<std::uint16_t>(g);
        std::size_t c = 0;
        for (; c + kBlock <= n; c += kBlock)
            group_candidates_block<Pixel, kBlock>(gm + c, lo.data() + c, hi.data() + c,
                                                  best.data() + c, best_group.data() + c, gg, first,
                                                  last, 0);
        group_candidates_block<Pixel, 0>(gm + c, lo.data() + c, hi.data() + c, best.data() + c,
                                         best_group.data() + c, gg, first, last, n - c);
    }

    SecondPeaks out{std::vector<int>(n, 0), std::vector<int>(n, -1)};
    for (std::size_t c = 0; c < n; ++c) {
        const Pixel* column = pixels + c;
        int value = best[c], row = -1;
        if (value > 0)  // the first row of the winning group reaching its maximum
            for (row = best_group[c] * kGroupRows; column[row * stride] != value; ++row) {
            }
        // The rows outside [lo, hi] of the groups the excluded rows cut; ties: the lower row.
        const auto consider = [&](int r0, int r1) {
            for (int r = r0; r <= r1; ++r) {
                const int v = column[r * stride];
                if (v > value || (v == value && v > 0 && r < row)) {
                    value = v;
                    row = r;
                }
            }
        };
        consider(lo[c] / kGroupRows * kGroupRows, lo[c] - 1);
        consider(hi[c] + 1, std::min((hi[c] / kGroupRows + 1) * kGroupRows, height) - 1);
        out.value[c] = value;
        out.row[c] = row;
    }
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

    // One pass over the image: per column the maximum and the first row reaching it, and the
    // maximum of every group of kGroupRows rows (for the second peak, below).
    const int n_groups = (height + kGroupRows - 1) / kGroupRows;
    std::vector<Pixel> peak(n, Pixel{0}),
        group_max(static_cast<std::size_t>(n_groups) * n, Pixel{0});
    std::vector<std::uint16_t> peak_row(n, 0);
    for (int r = 0; r < height; ++r)
        running_max(pixels + r * stride, peak.data(), peak_row.data(),
                    group_max.data() + static_cast<std::size_t>(r / kGroupRows) * n,
                    static_cast<std::uint16_t>(r), n);

    const SecondPeaks second = config.double_peak_ratio > 0.0
                                   ? second_peaks(pixels, stride, height, group_max, peak_row,
                                                  config.double_peak_min_separation_px)
                                   : SecondPeaks{};

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
        if (config.double_peak_ratio > 0.0 && second.value[c] > 0) {
            // Both peaks' contrast as the mean over their 3 central rows, each against its own
            // flanks: a glow gradient rising along the column is not a peak, a single noisy
            // pixel hardly is, a reflection (a line, several pixels wide) is.
            const int m2 = second.row[c];
            const double contrast2 = peak_contrast(
                column, stride, height, m2, local_background(column, stride, height, m2, config));
            if (contrast2 >=
                config.double_peak_ratio * peak_contrast(column, stride, height, m, background)) {
                point.status = StripeStatus::kDoublePeak;
                continue;
            }
        }

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
