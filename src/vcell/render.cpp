#include "hotgauge/vcell/render.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include "hotgauge/sim/geometry.hpp"

namespace hotgauge::vcell {
namespace {

// A fixed table of standard normal deviates, read from a random start each row: a 2048 × 1088
// frame needs two million deviates at up to 100 frames/s; drawing each one costs more than the
// rest of the rendering. Period 2^16, far longer than any correlation the extraction sees.
const std::vector<float>& normal_table() {
    static const std::vector<float> table = [] {
        sim::RandomStream rng(0x5eed);
        std::vector<float> t(1 << 16);
        for (auto& v : t) v = static_cast<float>(rng.normal());
        return t;
    }();
    return table;
}

}  // namespace

core::Result<acquire::Triangulation> sensor_triangulation(const sim::SensorConfig& s,
                                                          int height_px) {
    return calib::triangulation(sim::sensor_model(s), height_px);
}

double glow_scale(double temperature_c) {
    if (temperature_c < 500.0) return 0.0;
    constexpr double kC2OverLambdaK = 14388.0 / 0.405;  // c2 / 405 nm, K
    auto planck = [](double t_k) { return 1.0 / std::expm1(kC2OverLambdaK / t_k); };
    return std::min(20.0, planck(temperature_c + 273.15) / planck(1273.15));
}

void render_stripe(std::span<const sim::RayReturn> returns,
                   const acquire::Triangulation& triangulation, const StripeLook& look,
                   double exposure_us, double glow_fraction, int width, int height, int offset_x,
                   int offset_y, int bytes_per_pixel, sim::RandomStream& rng,
                   std::span<std::uint8_t> out) {
    const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    std::vector<float> img(n, 0.0f);
    const float full = static_cast<float>(look.full_scale);
    const double exposure = exposure_us > 0 ? exposure_us / look.reference_exposure_us : 1.0;
    const auto& table = normal_table();
    const std::size_t mask = table.size() - 1;

    // Per column: where the stripe is and how bright (a diffuse surface: √cos of the incidence).
    std::vector<float> stripe_row(static_cast<std::size_t>(width), -1.0f);
    std::vector<float> amplitude(static_cast<std::size_t>(width), 0.0f);
    for (int c = 0; c < width; ++c) {
        const auto ray = static_cast<std::size_t>(c + offset_x);
        if (ray >= returns.size() || std::isnan(returns[ray].x_mm)) continue;
        const auto im = triangulation.to_image(returns[ray].x_mm, returns[ray].z_mm);
        if (std::isnan(im.v_px)) continue;
        stripe_row[c] = static_cast<float>(im.v_px - offset_y);
        amplitude[c] = static_cast<float>(look.peak_fraction * full * exposure *
                                          std::sqrt(std::max(0.0f, returns[ray].cos_incidence)));
    }
    const float glow = static_cast<float>(glow_fraction * full * exposure);
    const float black = static_cast<float>(look.black_level * full);
    // The stripe: a Gaussian across rows with multiplicative speckle; some columns also see a
    // reflection of it elsewhere on the part.
    const double sigma = look.sigma_px;
    const int reach = static_cast<int>(std::ceil(5.0 * sigma));
    auto draw = [&](int c, double v, float a) {
        const int r0 = std::max(0, static_cast<int>(std::floor(v)) - reach);
        const int r1 = std::min(height - 1, static_cast<int>(std::ceil(v)) + reach);
        for (int r = r0; r <= r1; ++r) {
            const double d = (r - v) / sigma;
            const float speckle =
                1.0f + static_cast<float>(look.speckle) *
                           table[(static_cast<std::size_t>(rng.engine()) >> 11) & mask];
            img[static_cast<std::size_t>(r) * width + c] +=
                a * speckle * static_cast<float>(std::exp(-0.5 * d * d));
        }
    };
    for (int c = 0; c < width; ++c) {
        if (stripe_row[c] < 0) continue;
        draw(c, stripe_row[c], amplitude[c]);
        if (rng.uniform() < look.reflection_fraction) {
            const double shift = (rng.uniform() < 0.5 ? -1 : 1) * (20.0 + 80.0 * rng.uniform());
            const double v = stripe_row[c] + shift;
            if (v > 0 && v < height - 1)
                draw(c, v, amplitude[c] * static_cast<float>(0.6 + 0.4 * rng.uniform()));
        }
    }
    // Background (black level, the glow as a smooth band where the column sees the part), shot
    // and read noise, quantisation, saturation: one pass straight into the output.
    const float read2 = static_cast<float>(look.read_noise * full * look.read_noise * full);
    const float inv_e = static_cast<float>(1.0 / look.electrons_per_count);
    const bool eight_bit = bytes_per_pixel == 1;
    if (out.size() < n * (eight_bit ? 1 : 2)) return;
    for (int r = 0; r < height; ++r) {
        std::size_t k = static_cast<std::size_t>(rng.engine()) & mask;
        const float band =
            glow * (0.6f + 0.4f * std::cos(6.283f * static_cast<float>(r + offset_y) / 700.0f));
        const std::size_t row0 = static_cast<std::size_t>(r) * static_cast<std::size_t>(width);
        const float* row = img.data() + row0;
        for (int c = 0; c < width; ++c) {
            const float s = black + (amplitude[c] > 0 ? band : 0.0f) + row[c];
            const float noisy = s + std::sqrt(read2 + s * inv_e) * table[k];
            k = (k + 1) & mask;
            // Round half up by truncation: the value is clamped non-negative first.
            const auto v = static_cast<std::uint16_t>(std::clamp(noisy, 0.0f, full) + 0.5f);
            const std::size_t i = row0 + static_cast<std::size_t>(c);
            if (eight_bit) {
                out[i] = static_cast<std::uint8_t>(v);
            } else {
                out[2 * i] = static_cast<std::uint8_t>(v & 0xff);  // little-endian (GVSP)
                out[2 * i + 1] = static_cast<std::uint8_t>(v >> 8);
            }
        }
    }
}

void render_peaks(std::span<const sim::RayReturn> returns,
                  const acquire::Triangulation& triangulation, const acquire::PeakFormat& format,
                  int width, int offset_x, int row_offset, std::uint16_t* rows) {
    const auto w = static_cast<std::size_t>(width);
    std::memset(rows, 0, w * static_cast<std::size_t>(format.rows_per_profile()) * 2);
    const double scale = std::ldexp(1.0, format.fractional_bits);
    std::uint16_t* intensity = format.intensity ? rows + (format.second_peak ? 2 : 1) * w : nullptr;
    for (int c = 0; c < width; ++c) {
        const auto ray = static_cast<std::size_t>(c + offset_x);
        if (ray >= returns.size() || std::isnan(returns[ray].x_mm)) continue;
        const auto im = triangulation.to_image(returns[ray].x_mm, returns[ray].z_mm);
        if (std::isnan(im.v_px)) continue;
        const double value = std::round((im.v_px - row_offset) * scale);
        if (value < 1.0 || value > 65535.0) continue;  // outside the camera's window
        rows[c] = static_cast<std::uint16_t>(value);
        if (intensity)
            intensity[c] = static_cast<std::uint16_t>(std::lround(
                static_cast<double>(returns[ray].cos_incidence) * format.intensity_max_value));
    }
}

}  // namespace hotgauge::vcell
