#pragma once
// Building blocks of the self-contained HTML reports (docs/results.md) and the daemon's status page
// (web): text escaped for HTML,
// numbers with a fixed number of decimals, pictures as PNG data: URIs (no file beside the page,
// no network).
#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "hotgauge/core/text.hpp"

namespace hotgauge::report {

// `text` with &, <, >, " and ' as entities (core::html_escape); `fixed`: core::fixed.
inline std::string escape(std::string_view text) { return core::html_escape(text); }
using core::fixed;

// An 8-bit RGB picture, row-major, 3 bytes per pixel.
struct RgbImage {
    int width = 0, height = 0;
    std::vector<std::uint8_t> rgb;
    RgbImage(int w, int h) : width(w), height(h), rgb(static_cast<std::size_t>(w) * h * 3, 0) {}
    void set(int x, int y, const std::array<std::uint8_t, 3>& c) {
        const std::size_t at = (static_cast<std::size_t>(y) * width + x) * 3;
        rgb[at] = c[0], rgb[at + 1] = c[1], rgb[at + 2] = c[2];
    }
};

// The picture as a PNG file's bytes.
std::vector<std::uint8_t> png_bytes(const RgbImage& image);
// "data:image/png;base64,…" of the picture, for an <img src>.
std::string png_data_uri(const RgbImage& image);

}  // namespace hotgauge::report
