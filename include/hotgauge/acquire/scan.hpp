#pragma once
// From camera frames to one face of a recording (docs/acquisition.md "Scans"): per frame, the
// laser line (image mode) or the camera's peaks (peaks mode), triangulated into profiles with
// their timestamps and positions. Pure: frames in, core::FaceScan out.
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "hotgauge/acquire/camera.hpp"
#include "hotgauge/acquire/stripe.hpp"
#include "hotgauge/acquire/triangulation.hpp"
#include "hotgauge/core/recording.hpp"

namespace hotgauge::acquire {

struct ScanConfig {
    // The face scanned: its name and geometry (a calibration's: calib::scan_config). The
    // positions are the true travel, speed × travel_scale × (t − t of the first profile).
    core::FaceGeometry face{.name = "top"};
    bool geometry_from_calibration = false;  // the recording says so (core::FaceScan)
    std::string frame_mode = "image";  // image: a picture of the stripe; peaks: profile frames
    StripeConfig stripe;
    PeakFormat peaks;
    int offset_x_px = 0, offset_y_px = 0;  // the camera region's offset (full-sensor pixels)
    double speed_mm_s = 200.0;             // the axis's commanded speed (constant velocity)
    // peaks mode: time between the profiles bundled in one frame (the line period), s.
    double line_period_s = 1e-3;
    std::int64_t clock_offset_ns = 0;  // added to camera timestamps: camera → accelerometer clock
};

// What became of the frames and points; goes into the recording's summary and the logs.
struct ScanStats {
    std::int64_t frames = 0, refused_frames = 0, profiles = 0;
    std::int64_t ok = 0, no_return = 0, dark = 0, saturated = 0, double_peak = 0;
    std::string last_refusal;  // why the last refused frame was refused
};

class ScanBuilder {
  public:
    ScanBuilder(ScanConfig config, Triangulation triangulation);
    // Adds a frame's profiles. A frame is refused (counted, never half-used) when its size does
    // not fit the mode or its timestamp does not follow the previous one.
    void add(const Frame& frame);
    const ScanStats& stats() const { return stats_; }
    // The face so far (moved out; the builder is empty afterwards).
    core::FaceScan take();

  private:
    void start_face();
    void refuse(const std::string& why);
    void add_profile(const std::vector<StripePoint>& points, std::size_t first, int width,
                     std::int64_t t_ns);

    ScanConfig config_;
    Triangulation triangulation_;
    core::FaceScan face_;
    ScanStats stats_;
    std::int64_t t_first_ns_ = 0;
    // Per-frame buffers, reused: a stream of frames allocates nothing after the first.
    std::vector<std::uint16_t> words_;
    std::vector<StripePoint> points_;
};

}  // namespace hotgauge::acquire
