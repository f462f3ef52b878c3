// Laser-line extraction and triangulation against oracles (style.md §6): rendered stripes with
// known sub-pixel centres (pixel-integrated Gaussians on a glowing background, fixed seeds),
// peak frames built by hand, the paper's Eq. 2 and a ray-traced thin lens written out here
// independently, and round trips over the whole field.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "hotgauge/acquire/stripe.hpp"
#include "hotgauge/acquire/triangulation.hpp"

namespace ha = hotgauge::acquire;
using ha::StripeStatus;

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDeg = kPi / 180.0;

// ---------------------------------------------------------------------------------------------
// Stripe images

struct Scene {
    int width = 256, height = 200;
    double sigma_px = 2.0;
    double amplitude = 1500.0;  // counts at the peak of a pixel-integrated σ ≫ 1 stripe
    // Glow: smooth, rising along rows and columns, slightly curved (a hot surface).
    double glow = 150.0, glow_per_row = 1.0, glow_per_column = 0.5, glow_curvature = 200.0;
    double read_noise = 0.0;  // counts σ
    double shot_gain = 0.0;   // variance per count of signal
    double speckle = 0.0;     // relative σ of the stripe, per pixel
    int max_value = 4095;
    std::uint64_t seed = 1;
};

// True centre of column c: sweeps every sub-pixel phase, stays clear of the borders.
double true_centre(const Scene& s, int c) {
    return 0.5 * s.height + 0.3 * s.height * std::sin(0.0211 * c) + 4.0 * std::sin(c / 7.3) +
           0.1234;
}

// ∫ over pixel r of exp(−(s − c)²/2σ²): what a pixel sees of a Gaussian line.
double pixel_gaussian(double r, double c, double sigma) {
    const double k = 1.0 / (sigma * std::numbers::sqrt2);
    return sigma * std::sqrt(kPi / 2.0) *
           (std::erf((r + 0.5 - c) * k) - std::erf((r - 0.5 - c) * k));
}

double glow(const Scene& s, int r, int c) {
    const double t = static_cast<double>(r) / s.height;
    return s.glow + s.glow_per_row * r + s.glow_per_column * c + s.glow_curvature * t * t;
}

// Column-major stripe values, added onto the image by callers that need more than one line.
template <class Pixel>
std::vector<Pixel> render(const Scene& s, const std::vector<double>& centres,
                          const std::vector<double>& amplitudes) {
    std::mt19937_64 rng(s.seed);
    std::normal_distribution<double> normal(0.0, 1.0);
    std::vector<Pixel> img(static_cast<std::size_t>(s.width) * s.height);
    for (int r = 0; r < s.height; ++r)
        for (int c = 0; c < s.width; ++c) {
            double stripe = amplitudes[c] * pixel_gaussian(r, centres[c], s.sigma_px);
            stripe *= 1.0 + s.speckle * normal(rng);
            double v = glow(s, r, c) + stripe;
            v += std::sqrt(s.read_noise * s.read_noise + s.shot_gain * std::max(v, 0.0)) *
                 normal(rng);
            img[static_cast<std::size_t>(r) * s.width + c] =
                static_cast<Pixel>(std::clamp(std::round(v), 0.0, double(s.max_value)));
        }
    return img;
}

struct Errors {
    double rms = 0, mean = 0, max_abs = 0;
    int ok = 0;
};

Errors errors(const std::vector<ha::StripePoint>& pts, const std::vector<double>& centres) {
    Errors e;
    double sum_sq = 0;
    for (std::size_t c = 0; c < pts.size(); ++c) {
        if (pts[c].status != StripeStatus::kOk) continue;
        const double d = pts[c].row - centres[c];
        sum_sq += d * d;
        e.mean += d;
        e.max_abs = std::max(e.max_abs, std::abs(d));
        ++e.ok;
    }
    e.rms = std::sqrt(sum_sq / std::max(e.ok, 1));
    e.mean /= std::max(e.ok, 1);
    return e;
}

ha::StripeConfig config_for(double sigma_px, int max_value, bool gaussian) {
    ha::StripeConfig cfg;
    cfg.max_value = max_value;
    cfg.window_half_width = std::max(3, static_cast<int>(std::ceil(3.0 * sigma_px)));
    cfg.background_band = 3;
    cfg.double_peak_min_separation_px = 2 * cfg.window_half_width + cfg.background_band + 2;
    cfg.gaussian_refinement = gaussian;
    return cfg;
}

std::vector<double> centres_of(const Scene& s) {
    std::vector<double> c(static_cast<std::size_t>(s.width));
    for (int i = 0; i < s.width; ++i) c[i] = true_centre(s, i);
    return c;
}

}  // namespace

TEST(Stripe, NoiseFreeSubPixelAccuracy) {
    for (double sigma : {1.0, 1.5, 2.0, 3.0}) {
        Scene s;
        s.sigma_px = sigma;
        const auto centres = centres_of(s);
        const auto img = render<std::uint16_t>(s, centres, std::vector<double>(s.width, 1500.0));
        for (bool gaussian : {false, true}) {
            const auto pts = ha::extract_stripe(img.data(), s.width, s.height, s.width,
                                                config_for(sigma, 4095, gaussian));
            const Errors e = errors(pts, centres);
            std::printf("noise-free  sigma %.1f px  %-8s  rms %.4f px  mean %+.4f  max %.4f\n",
                        sigma, gaussian ? "gaussian" : "cog", e.rms, e.mean, e.max_abs);
            EXPECT_EQ(e.ok, s.width);
            EXPECT_LE(e.rms, 0.05) << "sigma " << sigma << (gaussian ? " gaussian" : " cog");
        }
    }
}

// Bias as a function of the sub-pixel phase of the true centre (the "S-curve"), noise-free:
// the centre of gravity over ±3σ is truncated and its background comes from the stripe's far
// tails; the log-parabola is exact for a Gaussian and only feels the pixel integration.
TEST(Stripe, CentreOfGravityBiasVersusGaussianRefinement) {
    for (double sigma : {1.0, 2.0}) {
        Scene s;
        s.width = 1000;
        s.sigma_px = sigma;
        const auto centres = centres_of(s);
        const auto img = render<std::uint16_t>(s, centres, std::vector<double>(s.width, 1500.0));
        double amplitude[2] = {};
        for (bool gaussian : {false, true}) {
            const auto pts = ha::extract_stripe(img.data(), s.width, s.height, s.width,
                                                config_for(sigma, 4095, gaussian));
            double sum[10] = {}, n[10] = {};
            for (int c = 0; c < s.width; ++c) {
                ASSERT_EQ(pts[c].status, StripeStatus::kOk);
                const double phase = centres[c] - std::floor(centres[c]);
                const int bin = std::min(9, static_cast<int>(phase * 10.0));
                sum[bin] += pts[c].row - centres[c];
                ++n[bin];
            }
            std::printf("bias by phase  sigma %.0f  %-8s:", sigma, gaussian ? "gaussian" : "cog");
            for (int bin = 0; bin < 10; ++bin) {
                ASSERT_GT(n[bin], 0);
                const double mean = sum[bin] / n[bin];
                std::printf(" %+.4f", mean);
                amplitude[gaussian] = std::max(amplitude[gaussian], std::abs(mean));
            }
            std::printf("\n");
        }
        EXPECT_LE(amplitude[0], 0.02) << sigma;
        EXPECT_LT(amplitude[1], amplitude[0]) << sigma;
    }
}

// Shot and read noise and 5 % pixel-to-pixel speckle on a glowing part. The centre of gravity
// averages 2w + 1 pixels, the log-parabola 3: a tenth of the bias (above) but noisier, the more so
// the wider the stripe. "Weak on glow" (SNR ≈ 10 at the peak) is past the 0.2 px specification:
// the centre of gravity is noise-limited there (≈ σ_noise·√(Σ(r − c)²) / Σ signal ≈ 0.2 px).
TEST(Stripe, RealisticNoiseOnGlow) {
    struct Case {
        const char* name;
        double sigma_px, amplitude, glow;
        double cog_max_rms, gaussian_max_rms;
    };
    for (const Case& k : {Case{"sigma 2, good contrast", 2.0, 1500.0, 150.0, 0.2, 0.5},
                          Case{"sigma 1, good contrast", 1.0, 1500.0, 150.0, 0.2, 0.2},
                          Case{"sigma 2, weak on glow", 2.0, 400.0, 600.0, 0.3, 1.0}}) {
        Scene s;
        s.width = 1000;
        s.sigma_px = k.sigma_px;
        s.amplitude = k.amplitude;
        s.glow = k.glow;
        s.glow_per_row = 0.5;
        s.glow_curvature = 100.0;
        s.read_noise = 4.0;  // counts, 12-bit camera
        s.shot_gain = 1.0;   // variance per count of signal
        s.speckle = 0.05;
        s.seed = 7;
        const auto centres = centres_of(s);
        const auto img =
            render<std::uint16_t>(s, centres, std::vector<double>(s.width, k.amplitude));
        for (bool gaussian : {false, true}) {
            const auto pts = ha::extract_stripe(img.data(), s.width, s.height, s.width,
                                                config_for(k.sigma_px, 4095, gaussian));
            const Errors e = errors(pts, centres);
            std::printf("noisy %-22s  %-8s  rms %.4f px  mean %+.4f  max %.4f  (%d of %d ok)\n",
                        k.name, gaussian ? "gaussian" : "cog", e.rms, e.mean, e.max_abs, e.ok,
                        s.width);
            EXPECT_EQ(e.ok, s.width) << k.name;
            EXPECT_LE(e.rms, gaussian ? k.gaussian_max_rms : k.cog_max_rms)
                << k.name << (gaussian ? " gaussian" : " cog");
        }
    }
}

TEST(Stripe, FlagsSaturatedDarkNoReturnAndDoublePeak) {
    Scene s;
    s.width = 160;
    s.read_noise = 2.0;
    const auto centres = centres_of(s);
    std::vector<double> amp(s.width, 1500.0);
    for (int c = 32; c < 48; ++c) amp[c] = 6000.0;  // saturated
    for (int c = 48; c < 64; ++c) amp[c] = 15.0;    // dark: below min_peak above the glow
    auto img = render<std::uint16_t>(s, centres, amp);
    const auto at = [&](int r, int c) -> std::uint16_t& {
        return img[static_cast<std::size_t>(r) * s.width + c];
    };
    // Columns 64–79: nothing at all (off the part, laser lost): no glow, no stripe.
    for (int r = 0; r < s.height; ++r)
        for (int c = 64; c < 80; ++c) at(r, c) = static_cast<std::uint16_t>(r % 3);
    // Columns 80–95: a reflection at 0.7 × the stripe, 40 rows away; 96–111: a weak one (0.2 ×).
    // Columns 112–127: glow rising by 1200 counts along the column, no reflection.
    for (int r = 0; r < s.height; ++r)
        for (int c = 80; c < 128; ++c) {
            const double ratio = c < 96 ? 0.7 : (c < 112 ? 0.2 : 0.0);
            double extra = ratio * 1500.0 * pixel_gaussian(r, centres[c] + 40.0, 2.0);
            if (c >= 112) extra += 1200.0 * r / s.height;
            at(r, c) = static_cast<std::uint16_t>(std::min(4095.0, at(r, c) + std::round(extra)));
        }

    const ha::StripeConfig cfg = config_for(2.0, 4095, false);
    ASSERT_TRUE(ha::check_stripe_config(cfg).ok());
    const auto pts = ha::extract_stripe(img.data(), s.width, s.height, s.width, cfg);
    const auto expected = [](int c) {
        if (c >= 32 && c < 48) return StripeStatus::kSaturated;
        if (c >= 48 && c < 64) return StripeStatus::kDark;
        if (c >= 64 && c < 80) return StripeStatus::kNoReturn;
        if (c >= 80 && c < 96) return StripeStatus::kDoublePeak;
        return StripeStatus::kOk;
    };
    for (int c = 0; c < s.width; ++c) {
        EXPECT_EQ(static_cast<int>(pts[c].status), static_cast<int>(expected(c))) << "column " << c;
        EXPECT_EQ(std::isnan(pts[c].row), pts[c].status != StripeStatus::kOk) << "column " << c;
        EXPECT_GE(pts[c].quality, 0.0F);
        EXPECT_LE(pts[c].quality, 1.0F);
        if (pts[c].status == StripeStatus::kOk) {
            EXPECT_NEAR(pts[c].row, centres[c], 0.1) << "column " << c;
        }
    }
    EXPECT_NEAR(pts[10].quality, 1500.0 / 4095.0, 0.05);
    EXPECT_LT(pts[50].quality, 40.0F / 4095.0F);
    EXPECT_EQ(pts[70].quality, 0.0F);

    // Double-peak detection off: the reflected columns are measured on the brighter line.
    ha::StripeConfig off = cfg;
    off.double_peak_ratio = 0.0;
    const auto pts_off = ha::extract_stripe(img.data(), s.width, s.height, s.width, off);
    for (int c = 80; c < 96; ++c) {
        ASSERT_EQ(pts_off[c].status, StripeStatus::kOk) << c;
        EXPECT_NEAR(pts_off[c].row, centres[c], 0.1) << "column " << c;
    }
}

TEST(Stripe, EightAndSixteenBit) {
    Scene s8;
    s8.max_value = 255;
    s8.glow = 10.0;
    s8.glow_per_row = 0.1;
    s8.glow_per_column = 0.05;
    s8.glow_curvature = 10.0;
    const auto centres = centres_of(s8);
    std::vector<double> amp8(s8.width, 180.0);
    for (int c = 200; c < 210; ++c) amp8[c] = 400.0;  // clips at 255
    const auto img8 = render<std::uint8_t>(s8, centres, amp8);
    ha::StripeConfig cfg8 = config_for(2.0, 255, false);
    cfg8.min_peak = 10.0;
    ASSERT_TRUE(ha::check_stripe_config(cfg8).ok());
    const auto pts8 = ha::extract_stripe(img8.data(), s8.width, s8.height, s8.width, cfg8);
    const Errors e8 = errors(pts8, centres);
    for (int c = 200; c < 210; ++c) EXPECT_EQ(pts8[c].status, StripeStatus::kSaturated) << c;
    EXPECT_EQ(e8.ok, s8.width - 10);

    Scene s16 = s8;
    s16.max_value = 65535;
    s16.glow = 3000.0;
    s16.glow_per_row = 10.0;
    s16.glow_per_column = 5.0;
    s16.glow_curvature = 2000.0;
    std::vector<double> amp16(s16.width, 30000.0);
    for (int c = 200; c < 210; ++c) amp16[c] = 90000.0;
    const auto img16 = render<std::uint16_t>(s16, centres, amp16);
    ha::StripeConfig cfg16 = config_for(2.0, 65535, false);
    cfg16.min_peak = 500.0;
    const auto pts16 = ha::extract_stripe(img16.data(), s16.width, s16.height, s16.width, cfg16);
    const Errors e16 = errors(pts16, centres);
    for (int c = 200; c < 210; ++c) EXPECT_EQ(pts16[c].status, StripeStatus::kSaturated) << c;
    EXPECT_EQ(e16.ok, s16.width - 10);

    std::printf("8-bit rms %.4f px, 16-bit rms %.4f px (noise-free, quantised)\n", e8.rms, e16.rms);
    EXPECT_LE(e8.rms, 0.05);
    EXPECT_LE(e16.rms, 0.05);
}

// Row-wise passes with a stride: padding never leaks in; stripes touching the image's edges
// and tiny images are handled.
TEST(Stripe, StrideEdgesAndTinyImages) {
    Scene s;
    const auto centres = centres_of(s);
    const auto img = render<std::uint16_t>(s, centres, std::vector<double>(s.width, 1500.0));
    const int stride = s.width + 37;
    std::vector<std::uint16_t> padded(static_cast<std::size_t>(stride) * s.height, 4095);
    for (int r = 0; r < s.height; ++r)
        std::copy_n(img.begin() + static_cast<std::ptrdiff_t>(r) * s.width, s.width,
                    padded.begin() + static_cast<std::ptrdiff_t>(r) * stride);
    const ha::StripeConfig cfg = config_for(2.0, 4095, true);
    const auto tight = ha::extract_stripe(img.data(), s.width, s.height, s.width, cfg);
    const auto loose = ha::extract_stripe(padded.data(), s.width, s.height, stride, cfg);
    for (int c = 0; c < s.width; ++c) {
        EXPECT_EQ(tight[c].status, loose[c].status);
        EXPECT_EQ(tight[c].row, loose[c].row);
    }

    // A stripe at the first and at the last row: found, centre within the clipped window.
    std::vector<std::uint16_t> edge(4 * 30, 100);
    for (int c = 0; c < 4; ++c) {
        const int r = c < 2 ? 0 : 29;
        edge[static_cast<std::size_t>(r) * 4 + c] = 2000;
        edge[static_cast<std::size_t>(r == 0 ? 1 : 28) * 4 + c] = 900;
    }
    for (const auto& p : ha::extract_stripe(edge.data(), 4, 30, 4, cfg)) {
        ASSERT_EQ(p.status, StripeStatus::kOk);
        EXPECT_TRUE((p.row > 0.0F && p.row < 0.5F) || (p.row > 28.5F && p.row < 29.0F)) << p.row;
    }
    const std::uint16_t one[3] = {5, 3000, 7};
    const auto single_row = ha::extract_stripe(one, 3, 1, 3, cfg);
    EXPECT_EQ(single_row[1].status, StripeStatus::kOk);  // no background: contrast vs 0
    EXPECT_EQ(single_row[1].row, 0.0F);
    EXPECT_TRUE(ha::extract_stripe(one, 0, 1, 3, cfg).empty());
}

TEST(Stripe, ConfigErrorsNameTheKey) {
    const auto message = [](auto mutate) {
        ha::StripeConfig cfg;
        mutate(cfg);
        const auto r = ha::check_stripe_config(cfg);
        return r.ok() ? std::string("ok") : r.error().message;
    };
    EXPECT_EQ(message([](ha::StripeConfig&) {}), "ok");
    EXPECT_NE(message([](ha::StripeConfig& c) { c.max_value = 4000; }).find("max_value"),
              std::string::npos);
    EXPECT_NE(
        message([](ha::StripeConfig& c) { c.saturation_level = 5000; }).find("saturation_level"),
        std::string::npos);
    EXPECT_NE(message([](ha::StripeConfig& c) { c.min_peak = 0; }).find("min_peak"),
              std::string::npos);
    EXPECT_NE(
        message([](ha::StripeConfig& c) { c.window_half_width = 0; }).find("window_half_width"),
        std::string::npos);
    EXPECT_NE(message([](ha::StripeConfig& c) { c.background_band = 0; }).find("background_band"),
              std::string::npos);
    EXPECT_NE(
        message([](ha::StripeConfig& c) { c.double_peak_ratio = 1.5; }).find("double_peak_ratio"),
        std::string::npos);
    EXPECT_NE(message([](ha::StripeConfig& c) {
                  c.double_peak_min_separation_px = 4;
              }).find("double_peak_min_separation_px"),
              std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Peak frames

TEST(Peaks, EveryValueWithSixFractionalBitsIsExact) {
    std::vector<std::uint16_t> row(65536);
    for (int v = 0; v < 65536; ++v) row[v] = static_cast<std::uint16_t>(v);
    const ha::PeakFormat format;  // 6 bits, peaks only, one profile
    ASSERT_TRUE(ha::check_peak_format(format).ok());
    const auto pts = ha::decode_peaks(row.data(), 65536, format);
    ASSERT_EQ(pts.size(), 65536U);
    EXPECT_EQ(pts[0].status, StripeStatus::kNoReturn);
    EXPECT_TRUE(std::isnan(pts[0].row));
    for (int v = 1; v < 65536; ++v) {
        ASSERT_EQ(pts[v].status, StripeStatus::kOk);
        ASSERT_EQ(pts[v].row, static_cast<float>(v / 64.0)) << v;
        ASSERT_EQ(pts[v].quality, 1.0F);
    }
    EXPECT_EQ(pts[65535].row, 1023.984375F);
}

// Layout (stripe.hpp): per profile the peak row, second-peak row, intensity row, width row;
// profiles one after the other.
TEST(Peaks, SeveralProfilesWithSecondPeakIntensityAndWidth) {
    ha::PeakFormat format;
    format.second_peak = true;
    format.intensity = true;
    format.peak_width = true;
    format.profiles_per_frame = 3;
    format.intensity_max_value = 255;
    ASSERT_EQ(format.rows_per_profile(), 4);
    ASSERT_EQ(format.frame_rows(), 12);
    const int width = 100;
    std::vector<std::uint16_t> frame(static_cast<std::size_t>(width) * format.frame_rows());
    const auto cell = [&](int profile, int part, int i) -> std::uint16_t& {
        return frame[(static_cast<std::size_t>(profile) * 4 + part) * width + i];
    };
    for (int k = 0; k < 3; ++k)
        for (int i = 0; i < width; ++i) {
            cell(k, 0, i) =
                static_cast<std::uint16_t>(i % 10 == 0 ? 0 : 64 * (100 * k + i) + i % 64);
            cell(k, 1, i) = static_cast<std::uint16_t>(i % 7 == 0 ? 5000 : 0);
            cell(k, 2, i) = static_cast<std::uint16_t>((i * 3 + k) % 256);
            cell(k, 3, i) = 0xBEEF;  // widths are read past
        }
    const auto pts = ha::decode_peaks(frame.data(), width, format);
    ASSERT_EQ(pts.size(), 300U);
    for (int k = 0; k < 3; ++k)
        for (int i = 0; i < width; ++i) {
            const ha::StripePoint& p = pts[static_cast<std::size_t>(k) * width + i];
            const float quality = static_cast<float>((i * 3 + k) % 256) / 255.0F;
            if (i % 10 == 0) {
                EXPECT_EQ(p.status, StripeStatus::kNoReturn);
                EXPECT_EQ(p.quality, 0.0F);
            } else if (i % 7 == 0) {
                EXPECT_EQ(p.status, StripeStatus::kDoublePeak) << k << " " << i;
                EXPECT_TRUE(std::isnan(p.row));
                EXPECT_FLOAT_EQ(p.quality, quality);
            } else {
                ASSERT_EQ(p.status, StripeStatus::kOk) << k << " " << i;
                EXPECT_EQ(p.row, static_cast<float>(100.0 * k + i + (i % 64) / 64.0));
                EXPECT_FLOAT_EQ(p.quality, quality);
            }
        }
    ha::PeakFormat bad;
    bad.fractional_bits = 16;
    EXPECT_NE(ha::check_peak_format(bad).error().message.find("fractional_bits"),
              std::string::npos);
    bad = {};
    bad.profiles_per_frame = 0;
    EXPECT_NE(ha::check_peak_format(bad).error().message.find("profiles_per_frame"),
              std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Triangulation

namespace {

ha::DirectBeamParams simulator_head() {
    auto p = ha::design_direct_beam({});
    EXPECT_TRUE(p.ok()) << (p.ok() ? "" : p.error().message);
    return *p;
}

ha::Triangulation make(const ha::DirectBeamParams& p) {
    auto t = ha::Triangulation::direct_beam(p);
    EXPECT_TRUE(t.ok()) << (t.ok() ? "" : t.error().message);
    return *t;
}

struct RoundTrip {
    double max_px = 0, max_mm = 0;
};

// (u, v) → (x, z) → (u, v) at every pixel of every column_step-th column and the last (at a
// fractional phase), and (x, z) → (u, v) → (x, z) on a grid covering the field's range and fan.
RoundTrip round_trip(const ha::Triangulation& t, double z_lo, double z_hi, int column_step = 1) {
    std::vector<int> columns;
    for (int c = 0; c < t.width_px(); c += column_step) columns.push_back(c);
    if (columns.back() != t.width_px() - 1) columns.push_back(t.width_px() - 1);
    RoundTrip rt;
    for (int r = 0; r < t.height_px(); ++r)
        for (int c : columns) {
            const double u = c + 0.37 * ((c + r) % 2 ? 1 : -1), v = r + 0.29;
            const ha::ProfilePoint p = t.to_camera(u, v);
            const ha::ImagePoint q = t.to_image(p.x_mm, p.z_mm);
            rt.max_px = std::max({rt.max_px, std::abs(q.u_px - u), std::abs(q.v_px - v)});
            if (std::isnan(q.u_px) || std::isnan(q.v_px)) rt.max_px = 1e9;
        }
    for (double z = z_lo; z <= z_hi; z += 0.731)
        for (double f = -0.49; f <= 0.49; f += 0.0123) {
            const double x = f * t.width_px() * 0.2 * z / 890.0;
            const ha::ImagePoint q = t.to_image(x, z);
            const ha::ProfilePoint p = t.to_camera(q.u_px, q.v_px);
            rt.max_mm = std::max({rt.max_mm, std::abs(p.x_mm - x), std::abs(p.z_mm - z)});
            if (std::isnan(p.x_mm) || std::isnan(p.z_mm)) rt.max_mm = 1e9;
        }
    return rt;
}

}  // namespace

TEST(Triangulation, DesignForTheSimulatorSensor) {
    const ha::DirectBeamParams p = simulator_head();
    std::printf(
        "simulator head: a0 %.4f mm  b0 %.4f mm  alpha %.4f deg  beta %.4f deg  "
        "v0 %.3f px  u0 %.1f px  pitch %.3f mm @ %.0f mm\n",
        p.a0_mm, p.b0_mm, p.alpha_deg, p.beta_deg, p.v0_px, p.u0_px, p.x_pitch_mm,
        p.reference_range_mm);
    EXPECT_NEAR(p.a0_mm * std::tan(p.alpha_deg * kDeg), p.b0_mm * std::tan(p.beta_deg * kDeg),
                1e-9);
    EXPECT_NEAR(std::tan(p.alpha_deg * kDeg), 300.0 / 890.0, 1e-12);
    const ha::Triangulation t = make(p);
    EXPECT_NEAR(t.to_camera(0, 0).z_mm, 600.0, 1e-6);
    EXPECT_NEAR(t.to_camera(2047, 1087).z_mm, 1200.0, 1e-6);
    EXPECT_NEAR(t.to_camera(1023.5, p.v0_px).z_mm, 890.0, 1e-9);
    const double slope_near = t.to_camera(0, 1).z_mm - t.to_camera(0, 0).z_mm;
    const double slope_far = t.to_camera(0, 1087).z_mm - t.to_camera(0, 1086).z_mm;
    std::printf("range per row: %.4f mm at 600 mm, %.4f mm at 1200 mm\n", slope_near, slope_far);
    // The simulator's ray i (x = (i − 1023.5)·0.2·z/890) is column i at every range.
    for (int i : {0, 1, 700, 1023, 1024, 2047})
        for (double z : {600.0, 777.7, 890.0, 1199.0}) {
            const ha::ImagePoint q = t.to_image((i - 1023.5) * 0.2 * z / 890.0, z);
            EXPECT_NEAR(q.u_px, i, 1e-9);
        }
    EXPECT_TRUE(std::isnan(t.to_image(0.0, 590.0).v_px));  // outside the range: not imaged
    EXPECT_TRUE(std::isnan(t.to_camera(0.0, 1088.0).z_mm));
}

TEST(Triangulation, DirectBeamRoundTripOverTheField) {
    const ha::Triangulation t = make(simulator_head());
    const RoundTrip rt = round_trip(t, 600.0, 1200.0);
    std::printf("direct beam round trip: %.3g px, %.3g mm\n", rt.max_px, rt.max_mm);
    EXPECT_LE(rt.max_px, 1e-6);
    EXPECT_LE(rt.max_mm, 1e-6);
}

// Eq. 2 as printed in the paper, and a thin lens ray-traced in the (y, z) plane: the laser along
// +z from the origin, the lens at angle α, the imager tilted at β about the image of the
// reference spot. Written independently of the implementation.
TEST(Triangulation, DirectBeamAgreesWithPaperEq2AndRayTracedLens) {
    ha::DirectBeamParams p;
    p.a0_mm = 250.0;
    p.b0_mm = 30.0;
    p.alpha_deg = 25.0;
    p.beta_deg = std::atan(p.a0_mm / p.b0_mm * std::tan(25.0 * kDeg)) / kDeg;  // Eq. 1
    p.pixel_size_mm = 0.0048;
    p.v0_px = 400.0;
    p.u0_px = 500.0;
    p.x_pitch_mm = 0.1;
    p.reference_range_mm = 300.0;
    p.width_px = 1000;
    p.height_px = 1000;
    const ha::Triangulation t = make(p);

    const double a0 = p.a0_mm, b0 = p.b0_mm, al = p.alpha_deg * kDeg, be = p.beta_deg * kDeg;
    const Eigen::Vector2d d(-std::sin(al), std::cos(al));  // lens axis (y, z), towards the spot
    const Eigen::Vector2d n(std::cos(al), std::sin(al));
    const Eigen::Vector2d lens = Eigen::Vector2d(0.0, p.reference_range_mm) - a0 * d;
    const Eigen::Vector2d spot_image = lens - b0 * d;
    const Eigen::Vector2d imager = std::cos(be) * d - std::sin(be) * n;  // rows grow along this
    const double f = a0 * b0 / (a0 + b0);                                // thin lens
    const auto cross = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
        return a.x() * b.y() - a.y() * b.x();
    };
    double max_eq2 = 0, max_ray = 0, max_focus = 0;
    for (double v = 0.0; v <= 999.0; v += 3.7) {
        const double x = (v - p.v0_px) * p.pixel_size_mm;
        const double y_paper =
            a0 * x * std::sin(be) / (b0 * std::sin(al) - x * std::sin(al + be));  // Eq. 2
        const ha::ProfilePoint q = t.to_camera(p.u0_px, v);
        max_eq2 = std::max(max_eq2, std::abs(q.z_mm - p.reference_range_mm - y_paper));

        // Chief ray from the lit point through the lens centre onto the tilted imager.
        const Eigen::Vector2d spot(0.0, q.z_mm);
        const Eigen::Vector2d ray = lens - spot;
        const double s = cross(spot_image - lens, imager) / cross(ray, imager);
        const Eigen::Vector2d hit = lens + s * ray;
        const double v_ray = p.v0_px + (hit - spot_image).dot(imager) / p.pixel_size_mm;
        max_ray = std::max(max_ray, std::abs(v_ray - v));

        // Eq. 1 puts the whole laser line in focus: the lit point's thin-lens image lies on
        // the imager.
        const double a = (spot - lens).dot(d), h = (spot - lens).dot(n);
        const double b = f * a / (a - f);
        const Eigen::Vector2d image = lens - b * d - h * b / a * n;
        max_focus = std::max(max_focus, std::abs(cross(image - spot_image, imager)));
    }
    std::printf("vs Eq. 2: %.3g mm; vs ray-traced lens: %.3g px; image off the imager: %.3g mm\n",
                max_eq2, max_ray, max_focus);
    EXPECT_LE(max_eq2, 1e-9);
    EXPECT_LE(max_ray, 1e-9);
    EXPECT_LE(max_focus, 1e-9);
}

TEST(Triangulation, BadParametersAreNamed) {
    const ha::DirectBeamParams good = simulator_head();
    const auto message = [&](auto mutate) {
        ha::DirectBeamParams p = good;
        mutate(p);
        auto t = ha::Triangulation::direct_beam(p);
        return t.ok() ? std::string("ok") : t.error().message;
    };
    const auto names = [&](auto mutate, const std::string& key) {
        const std::string m = message(mutate);
        EXPECT_NE(m.find(key), std::string::npos) << m;
    };
    EXPECT_EQ(message([](ha::DirectBeamParams&) {}), "ok");
    names([](ha::DirectBeamParams& p) { p.a0_mm = -1; }, "a0_mm");
    names([](ha::DirectBeamParams& p) { p.b0_mm = 0; }, "b0_mm");
    names([](ha::DirectBeamParams& p) { p.alpha_deg = 90; }, "alpha_deg");
    names([](ha::DirectBeamParams& p) { p.pixel_size_mm = std::nan(""); }, "pixel_size_mm");
    names([](ha::DirectBeamParams& p) { p.x_pitch_mm = 0; }, "x_pitch_mm");
    names([](ha::DirectBeamParams& p) { p.reference_range_mm = 0; }, "reference_range_mm");
    names([](ha::DirectBeamParams& p) { p.height_px = 1; }, "height_px");
    // tanβ = (b0/a0)·tanα instead of Eq. 1's (a0/b0)·tanα.
    names(
        [](ha::DirectBeamParams& p) {
            p.beta_deg = std::atan(p.b0_mm / p.a0_mm * std::tan(p.alpha_deg * kDeg)) / kDeg;
        },
        "beta_deg");
    const std::string scheimpflug = message([](ha::DirectBeamParams& p) { p.beta_deg = 80; });
    EXPECT_NE(scheimpflug.find("Scheimpflug"), std::string::npos) << scheimpflug;
    EXPECT_NE(scheimpflug.find(std::to_string(good.beta_deg).substr(0, 6)), std::string::npos)
        << scheimpflug;
    // The pole of Eq. 2 inside the field: no valid range for the far rows.
    const std::string pole = message([](ha::DirectBeamParams& p) { p.v0_px = -1500; });
    EXPECT_NE(pole.find("pole"), std::string::npos) << pole;
    EXPECT_NE(pole.find("v0_px"), std::string::npos) << pole;
    // Rows imaging behind the camera.
    const std::string behind = message([](ha::DirectBeamParams& p) { p.reference_range_mm = 100; });
    EXPECT_NE(behind.find("behind the camera"), std::string::npos) << behind;

    ha::DirectBeamDesign design;
    design.min_range_mm = 950.0;
    EXPECT_NE(ha::design_direct_beam(design).error().message.find("min_range_mm"),
              std::string::npos);
}

namespace {

// A calibration as it would be done: a flat target stepped through the range (25 mm steps), one
// stripe row per column and step, x from the fan.
std::vector<ha::CalibrationSample> plane_steps(const ha::Triangulation& truth,
                                               double z_shift_per_row2 = 0.0) {
    std::vector<ha::CalibrationSample> samples;
    for (double z = 600.0; z <= 1200.0; z += 25.0)
        for (int c = 0; c < truth.width_px(); ++c) {
            const double x = (c - 1023.5) * 0.2 * z / 890.0;
            const ha::ImagePoint q = truth.to_image(x, z);
            const double t = (q.v_px - 543.5) / 543.5;
            samples.push_back({q.u_px, q.v_px, x, z + z_shift_per_row2 * t * t * t});
        }
    return samples;
}

}  // namespace

TEST(Triangulation, CalibratedModelFromDirectBeamSamples) {
    const ha::Triangulation truth = make(simulator_head());
    const auto samples = plane_steps(truth);
    auto fit = ha::fit_calibrated_model(samples, {});
    ASSERT_TRUE(fit.ok()) << fit.error().message;
    auto model = ha::Triangulation::calibrated(fit->model);
    ASSERT_TRUE(model.ok()) << model.error().message;
    double max_z = 0, max_x = 0;
    for (double u = 0.0; u <= 2047.0; u += 40.93)
        for (double v = -0.5; v <= 1087.5; v += 0.77) {
            const ha::ProfilePoint a = truth.to_camera(u, v), b = model->to_camera(u, v);
            max_z = std::max(max_z, std::abs(a.z_mm - b.z_mm));
            max_x = std::max(max_x, std::abs(a.x_mm - b.x_mm));
        }
    const RoundTrip rt = round_trip(*model, 600.0, 1200.0, 7);
    std::printf(
        "calibrated (degree 3, %zu samples): fit rms %.3g mm; vs direct beam over the "
        "field: z %.3g mm, x %.3g mm; round trip %.3g px, %.3g mm; u0 %.6f pitch %.8f\n",
        samples.size(), fit->rms_z_mm, max_z, max_x, rt.max_px, rt.max_mm, fit->model.u0_px,
        fit->model.x_pitch_mm);
    EXPECT_LE(max_z, 1e-3);
    EXPECT_LE(max_x, 1e-3);
    EXPECT_LE(rt.max_px, 1e-6);
    EXPECT_LE(rt.max_mm, 1e-6);
    EXPECT_NEAR(fit->model.u0_px, 1023.5, 1e-6);
    EXPECT_NEAR(fit->model.x_pitch_mm, 0.2, 1e-9);

    // A lens whose range law departs from Eq. 2 (by 0.5·t³ mm, t the normalised row): absorbed
    // by the numerator's higher terms.
    const auto bent = plane_steps(truth, 0.5);
    auto fit5 = ha::fit_calibrated_model(bent, {.degree = 5});
    ASSERT_TRUE(fit5.ok()) << fit5.error().message;
    auto model5 = ha::Triangulation::calibrated(fit5->model);
    ASSERT_TRUE(model5.ok()) << model5.error().message;
    double max_bent = 0;
    for (double u = 0.0; u <= 2047.0; u += 40.93)
        for (double v = -0.5; v <= 1087.5; v += 0.77) {
            const double t = (v - 543.5) / 543.5;
            const double z = truth.to_camera(u, v).z_mm + 0.5 * t * t * t;
            max_bent = std::max(max_bent, std::abs(model5->to_camera(u, v).z_mm - z));
        }
    std::printf("calibrated (degree 5) on a bent range law: z %.3g mm over the field\n", max_bent);
    EXPECT_LE(max_bent, 1e-3);
}

// A lens that bends each column off the fan's ray (x scaled by 1 + 0.003·t², t the normalised
// row, 0.3 % at the field's top and bottom): the fan law cannot follow it, the per-column x law
// (x_degree 2) can, and to_image still inverts to_camera.
TEST(Triangulation, CalibratedModelPerColumnXLaw) {
    const ha::Triangulation truth = make(simulator_head());
    auto samples = plane_steps(truth);
    const auto bend = [](double v) {
        const double t = (v - 543.5) / 543.5;
        return 1.0 + 0.003 * t * t;
    };
    for (auto& s : samples) s.x_mm *= bend(s.v_px);
    auto fan = ha::fit_calibrated_model(samples, {});
    ASSERT_TRUE(fan.ok()) << fan.error().message;
    auto fit = ha::fit_calibrated_model(samples, {.x_degree = 2});
    ASSERT_TRUE(fit.ok()) << fit.error().message;
    auto model = ha::Triangulation::calibrated(fit->model);
    ASSERT_TRUE(model.ok()) << model.error().message;
    double max_x = 0;
    for (double u = 0.0; u <= 2047.0; u += 40.93)
        for (double v = -0.5; v <= 1087.5; v += 0.77)
            max_x = std::max(max_x, std::abs(truth.to_camera(u, v).x_mm * bend(v) -
                                             model->to_camera(u, v).x_mm));
    const RoundTrip rt = round_trip(*model, 600.0, 1200.0, 7);
    std::printf(
        "per-column x law: fit x rms %.3g mm (fan law %.3g mm), over the field %.3g mm; "
        "round trip %.3g px, %.3g mm\n",
        fit->rms_x_mm, fan->rms_x_mm, max_x, rt.max_px, rt.max_mm);
    EXPECT_GT(fan->rms_x_mm, 0.05);
    EXPECT_LE(fit->rms_x_mm, 1e-6);
    EXPECT_LE(max_x, 1e-6);
    EXPECT_LE(rt.max_px, 1e-6);
    EXPECT_LE(rt.max_mm, 1e-6);

    ha::CalibratedModel bad = fit->model;
    bad.x_coefficients.pop_back();
    auto t = ha::Triangulation::calibrated(bad);
    ASSERT_FALSE(t.ok());
    EXPECT_NE(t.error().message.find("x_coefficients: 6144 expected"), std::string::npos)
        << t.error().message;
    bad = fit->model;
    bad.x_coefficients[3 * 500] = bad.x_coefficients[3 * 501];  // column 500's x/z = column 501's
    t = ha::Triangulation::calibrated(bad);
    ASSERT_FALSE(t.ok());
    EXPECT_NE(t.error().message.find("does not grow from column 500 to 501"), std::string::npos)
        << t.error().message;
}

TEST(Triangulation, CalibrationErrors) {
    const ha::Triangulation truth = make(simulator_head());
    auto samples = plane_steps(truth);
    // Column 17 seen at four ranges only.
    std::erase_if(samples, [](const ha::CalibrationSample& s) {
        return std::lround(s.u_px) == 17 && s.z_mm > 680.0;
    });
    auto fit = ha::fit_calibrated_model(samples, {});
    ASSERT_FALSE(fit.ok());
    EXPECT_NE(fit.error().message.find("column 17"), std::string::npos) << fit.error().message;

    samples = plane_steps(truth);
    samples[5].v_px = 2000.0;
    fit = ha::fit_calibrated_model(samples, {});
    ASSERT_FALSE(fit.ok());
    EXPECT_NE(fit.error().message.find("sample 5"), std::string::npos) << fit.error().message;

    ha::CalibratedModel folded;
    folded.width_px = 2;
    folded.height_px = 10;
    folded.degree = 2;
    folded.coefficients = {900, 0, 50, 0, 900, 10, 0, 0};  // column 0: a parabola in the row
    folded.x_pitch_mm = 0.2;
    folded.reference_range_mm = 890;
    auto t = ha::Triangulation::calibrated(folded);
    ASSERT_FALSE(t.ok());
    EXPECT_NE(t.error().message.find("column 0"), std::string::npos) << t.error().message;
    EXPECT_NE(t.error().message.find("monotonic"), std::string::npos) << t.error().message;
}

TEST(Triangulation, ProfileIntoFaceScanLayout) {
    const ha::Triangulation t = make(simulator_head());
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const std::vector<ha::StripePoint> profile = {{100.25F, 0.5F, StripeStatus::kOk},
                                                  {nan, 0.0F, StripeStatus::kNoReturn},
                                                  {40.0F, 0.9F, StripeStatus::kOk},
                                                  {nan, 0.3F, StripeStatus::kDoublePeak}};
    std::vector<float> xz = {1.0F, 2.0F};  // one earlier point stays
    ha::triangulate(t, profile, xz, 1000.0, 64.0);
    ASSERT_EQ(xz.size(), 10U);
    EXPECT_EQ(xz[0], 1.0F);
    const ha::ProfilePoint p0 = t.to_camera(1000.0, 164.25), p2 = t.to_camera(1002.0, 104.0);
    EXPECT_EQ(xz[2], static_cast<float>(p0.x_mm));
    EXPECT_EQ(xz[3], static_cast<float>(p0.z_mm));
    EXPECT_TRUE(std::isnan(xz[4]) && std::isnan(xz[5]));
    EXPECT_EQ(xz[6], static_cast<float>(p2.x_mm));
    EXPECT_EQ(xz[7], static_cast<float>(p2.z_mm));
    EXPECT_TRUE(std::isnan(xz[8]) && std::isnan(xz[9]));
}
