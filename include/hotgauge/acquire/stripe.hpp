#pragma once
// Laser-line extraction (docs/acquisition.md "Stripe extraction", "Peak profiles"): per image
// column, the sub-pixel row of the laser stripe, or why there is none. Pure functions on pixel
// buffers: no camera, no files, no threads.
//
// Row convention (both frame modes): row r is the centre of pixel row r, so an image of height H
// covers rows [−0.5, H − 0.5]; rows are relative to the delivered frame (add the camera's OffsetY
// for full-sensor rows before triangulating).
#include <cstddef>
#include <cstdint>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::acquire {

enum class StripeStatus : std::uint8_t {
    kOk,          // row is the stripe centre
    kNoReturn,    // nothing lit: the column's maximum is below min_peak (or peak value 0)
    kDark,        // something lit, but the peak stands less than min_peak above its background
    kSaturated,   // a pixel in the window around the peak reaches saturation_level
    kDoublePeak,  // a second peak (a reflection) of at least double_peak_ratio × the first
};

struct StripePoint {
    float row;      // sub-pixel stripe centre; NaN unless status == kOk
    float quality;  // [0, 1]: peak contrast above the local background / max_value (0: none)
    StripeStatus status;
};

struct StripeConfig {
    int max_value = 4095;              // full scale of the pixel format: 2^bits − 1, bits 8..16
    int saturation_level = 0;          // a pixel ≥ this is saturated; 0: max_value
    double min_peak = 40.0;            // counts the peak must stand above the local background
    int window_half_width = 4;         // px: centre of gravity over rows [peak − w, peak + w]
    int background_band = 3;           // px on each side just outside the window: local background
    bool gaussian_refinement = false;  // Gaussian 3-point (log-parabola) fit at the peak
    double double_peak_ratio = 0.5;  // second-peak contrast ≥ this × first: kDoublePeak; 0: off
    int double_peak_min_separation_px = 10;  // a second peak lies farther than this; > w
};

// Checks a configuration (the app calls it at start and reports the message with the config
// key). extract_stripe asserts a valid configuration.
core::Result<void> check_stripe_config(const StripeConfig& config);

// One StripePoint per column of a width × height image whose row r starts at
// pixels + r · stride_pixels. The 8-bit overload needs config.max_value ≤ 255.
std::vector<StripePoint> extract_stripe(const std::uint16_t* pixels, int width, int height,
                                        std::ptrdiff_t stride_pixels, const StripeConfig& config);
std::vector<StripePoint> extract_stripe(const std::uint8_t* pixels, int width, int height,
                                        std::ptrdiff_t stride_pixels, const StripeConfig& config);

// Peak frames of profile cameras (Mono16). A frame holds profiles_per_frame profiles one after
// the other; each profile is rows_per_profile() rows of `width` values, in this order:
//   peak row (always), second-peak row (if second_peak), intensity row (if intensity),
//   width row (if peak_width).
// Peak values are rows with `fractional_bits` fractional bits (row = value / 2^bits); 0 = no
// return. With 6 bits the largest row is 1023.98: the camera's region must be ≤ 1024 rows high.
struct PeakFormat {
    int fractional_bits = 6;  // Photonfocus 3D cameras: 6
    bool second_peak = false;
    bool intensity = false;
    bool peak_width = false;  // read past, not reported
    int profiles_per_frame = 1;
    int intensity_max_value = 4095;  // quality = intensity / this (1 without intensity row)

    int rows_per_profile() const { return 1 + int{second_peak} + int{intensity} + int{peak_width}; }
    int frame_rows() const { return profiles_per_frame * rows_per_profile(); }
};

core::Result<void> check_peak_format(const PeakFormat& format);

// Decodes one frame of width × format.frame_rows() values. Returns profiles_per_frame × width
// points, profile k at [k · width, (k + 1) · width). A column with both peaks non-zero is
// kDoublePeak (the camera cannot tell the laser from its reflection); first peak 0: kNoReturn.
std::vector<StripePoint> decode_peaks(const std::uint16_t* data, int width,
                                      const PeakFormat& format);
// The same into `out` (resized), so that a stream of frames reuses one buffer.
void decode_peaks(const std::uint16_t* data, int width, const PeakFormat& format,
                  std::vector<StripePoint>& out);

}  // namespace hotgauge::acquire
