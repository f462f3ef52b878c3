#pragma once
// What the virtual camera shows (docs/virtual-cell.md "Rendering"): from one fan's returns to an
// image of the laser stripe (intensity profile, speckle, shot and read noise, the hot part's
// glow) or to a profile camera's peak rows. Pure functions; the noise comes from the caller's
// stream.
#include <cstdint>
#include <span>
#include <vector>

#include "hotgauge/acquire/stripe.hpp"
#include "hotgauge/acquire/triangulation.hpp"
#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/sim/scene.hpp"
#include "hotgauge/sim/simulator.hpp"

namespace hotgauge::vcell {

struct StripeLook {
    int full_scale = 4095;       // counts at saturation: 255 for Mono8, 4095 for 12 bits in Mono16
    double sigma_px = 1.2;       // the stripe's Gaussian width across rows
    double peak_fraction = 0.6;  // stripe peak on a surface facing the sensor, at the reference
    double reference_exposure_us = 100.0;  // exposure: brightness scales with it
    double speckle = 0.05;                 // relative σ of the stripe's multiplicative speckle
    double read_noise = 0.002;             // σ, fraction of full scale
    double electrons_per_count = 4.0;      // shot noise: σ² = counts / this
    double black_level = 0.004;            // fraction of full scale
    double glow = 0.03;  // hot part's glow where the part is in view, fraction of full
                         // scale (scaled by the temperature; 0 when cold)
    double reflection_fraction = 0.002;  // columns with a second, reflected stripe
};

// The sensor of a cell config as a direct-beam triangulation (acquire::design_direct_beam):
// one column per ray of the fan, rows over the measuring range.
core::Result<acquire::Triangulation> sensor_triangulation(const sim::SensorConfig& sensor,
                                                          int height_px = 1088);

// Glow of a part at `temperature_c` relative to StripeLook::glow at 1 000 °C (Planck's law at
// 405 nm through the sensor's filter, normalised); 0 below 500 °C.
double glow_scale(double temperature_c);

// Renders one stripe image (width × height pixels of bytes_per_pixel, full-sensor region offset
// (offset_x, offset_y)); ray i of `returns` is column i of the sensor.
void render_stripe(std::span<const sim::RayReturn> returns,
                   const acquire::Triangulation& triangulation, const StripeLook& look,
                   double exposure_us, double glow_fraction, int width, int height, int offset_x,
                   int offset_y, int bytes_per_pixel, sim::RandomStream& rng,
                   std::span<std::uint8_t> out);

// Writes one profile's rows of a peaks frame (format.rows_per_profile() rows of `width` Mono16
// values at `rows`): peak row = (v − row_offset) · 2^fractional_bits, 0 = no return or outside
// the window; intensity row (if any) = cos(incidence) · intensity_max_value.
void render_peaks(std::span<const sim::RayReturn> returns,
                  const acquire::Triangulation& triangulation, const acquire::PeakFormat& format,
                  int width, int offset_x, int row_offset, std::uint16_t* rows);

}  // namespace hotgauge::vcell
