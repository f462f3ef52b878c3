#include "hotgauge/acquire/scan.hpp"

#include <cmath>
#include <cstring>
#include <limits>

namespace hotgauge::acquire {

ScanBuilder::ScanBuilder(ScanConfig config, Triangulation triangulation)
    : config_(std::move(config)), triangulation_(std::move(triangulation)) {
    start_face();
}

// The face's geometry and what the scan applies (travel scale, clock offset), as its recording
// says them; no profile yet.
void ScanBuilder::start_face() {
    face_ = {};
    face_.geometry() = config_.face;
    face_.scan_direction.normalize();
    face_.clock_offset_ns = config_.clock_offset_ns;
    face_.geometry_from_calibration = config_.geometry_from_calibration;
}

void ScanBuilder::refuse(const std::string& why) {
    ++stats_.refused_frames;
    stats_.last_refusal = why;
}

void ScanBuilder::add_profile(const std::vector<StripePoint>& points, std::size_t first, int width,
                              std::int64_t t_ns) {
    if (face_.profile_times_ns.empty()) t_first_ns_ = t_ns;
    const std::span<const StripePoint> profile(points.data() + first,
                                               static_cast<std::size_t>(width));
    for (const auto& p : profile) switch (p.status) {
            case StripeStatus::kOk:
                ++stats_.ok;
                break;
            case StripeStatus::kNoReturn:
                ++stats_.no_return;
                break;
            case StripeStatus::kDark:
                ++stats_.dark;
                break;
            case StripeStatus::kSaturated:
                ++stats_.saturated;
                break;
            case StripeStatus::kDoublePeak:
                ++stats_.double_peak;
                break;
        }
    triangulate(triangulation_, profile, face_.profiles_mm, config_.offset_x_px,
                config_.offset_y_px);
    face_.profile_times_ns.push_back(t_ns);
    face_.profile_positions_mm.push_back(config_.speed_mm_s * config_.face.travel_scale *
                                         static_cast<double>(t_ns - t_first_ns_) * 1e-9);
    ++stats_.profiles;
}

void ScanBuilder::add(const Frame& f) {
    ++stats_.frames;
    if (face_.width == 0) face_.width = f.width;
    if (f.width != face_.width) {
        refuse("frame width " + std::to_string(f.width) + " differs from the scan's " +
               std::to_string(face_.width));
        return;
    }
    const std::int64_t t0 = f.camera_ns + config_.clock_offset_ns;
    const bool peaks = config_.frame_mode == "peaks";
    const int n = peaks ? config_.peaks.profiles_per_frame : 1;
    const auto period_ns = static_cast<std::int64_t>(std::llround(config_.line_period_s * 1e9));
    if (!face_.profile_times_ns.empty() && t0 <= face_.profile_times_ns.back()) {
        refuse("timestamp " + std::to_string(t0) + " ns does not follow the previous profile");
        return;
    }
    std::vector<StripePoint>& points = points_;
    if (peaks && !f.parts.empty()) {
        // Multi-part: one part per row kind (peak, then second peak / intensity / width as the
        // format has them), each profiles_per_frame rows; interleaved into the one-frame layout.
        const int kinds = config_.peaks.rows_per_profile();
        const int n_profiles = config_.peaks.profiles_per_frame;
        const auto w = static_cast<std::size_t>(f.width);
        bool fits = static_cast<int>(f.parts.size()) == kinds;
        for (const auto& part : f.parts)
            fits = fits && part.bytes_per_pixel == 2 && part.width == f.width &&
                   part.height >= n_profiles;
        if (!fits) {
            refuse("multi-part peaks frame is not " + std::to_string(kinds) + " Mono16 parts of " +
                   std::to_string(n_profiles) + " rows");
            return;
        }
        words_.resize(w * static_cast<std::size_t>(kinds * n_profiles));
        for (int k = 0; k < n_profiles; ++k)
            for (int j = 0; j < kinds; ++j)
                std::memcpy(words_.data() + (static_cast<std::size_t>(k * kinds + j)) * w,
                            f.data.data() + f.parts[j].offset + static_cast<std::size_t>(k) * w * 2,
                            w * 2);
        decode_peaks(words_.data(), f.width, config_.peaks, points);
    } else if (peaks) {
        if (f.bytes_per_pixel != 2 || f.height < config_.peaks.frame_rows()) {
            refuse("peaks frame is not Mono16 with " + std::to_string(config_.peaks.frame_rows()) +
                   " rows");
            return;
        }
        words_.resize(f.data.size() / 2);
        std::memcpy(words_.data(), f.data.data(), words_.size() * 2);
        decode_peaks(words_.data(), f.width, config_.peaks, points);
    } else if (f.bytes_per_pixel == 1) {
        points = extract_stripe(f.data.data(), f.width, f.height, f.width, config_.stripe);
    } else if (f.bytes_per_pixel == 2) {
        words_.resize(f.data.size() / 2);
        std::memcpy(words_.data(), f.data.data(), words_.size() * 2);
        points = extract_stripe(words_.data(), f.width, f.height, f.width, config_.stripe);
    } else {
        refuse("unsupported pixel size " + std::to_string(f.bytes_per_pixel) + " bytes");
        return;
    }
    for (int k = 0; k < n; ++k)
        add_profile(points, static_cast<std::size_t>(k) * static_cast<std::size_t>(f.width),
                    f.width, t0 + k * period_ns);
}

core::FaceScan ScanBuilder::take() {
    core::FaceScan out = std::move(face_);
    start_face();
    return out;
}

}  // namespace hotgauge::acquire
