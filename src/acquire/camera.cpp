// Aravis adapter (docs/acquisition.md). Aravis reports errors through GError; each is turned into
// a core::Error naming the device and the setting, and freed here.
#include "hotgauge/acquire/camera.hpp"

#include <arv.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <thread>

#include "hotgauge/core/clock.hpp"

namespace hotgauge::acquire {
namespace {

// Takes ownership of a GError: its message, or "" when there was none.
std::string take(GError*& e) {
    if (!e) return {};
    std::string m = e->message ? e->message : "unknown Aravis error";
    g_clear_error(&e);
    return m;
}

// A multi-part buffer's parts into `f` (parts one after the other in f.data); false when a part
// is missing or not a whole image.
bool copy_parts(ArvBuffer* b, Frame& f) {
    const guint n = arv_buffer_get_n_parts(b);
    if (n == 0) return false;
    for (guint i = 0; i < n; ++i) {
        size_t size = 0;
        const auto* data = static_cast<const std::uint8_t*>(arv_buffer_get_part_data(b, i, &size));
        FramePart part;
        part.component = static_cast<int>(arv_buffer_get_part_component_id(b, i));
        part.width = arv_buffer_get_part_width(b, i);
        part.height = arv_buffer_get_part_height(b, i);
        part.bytes_per_pixel = static_cast<int>(
            (ARV_PIXEL_FORMAT_BIT_PER_PIXEL(arv_buffer_get_part_pixel_format(b, i)) + 7) / 8);
        part.offset = f.data.size();
        part.size = static_cast<std::size_t>(part.width) * static_cast<std::size_t>(part.height) *
                    static_cast<std::size_t>(part.bytes_per_pixel);
        if (!data || part.width <= 0 || part.height <= 0 || size < part.size) return false;
        f.data.insert(f.data.end(), data, data + part.size);
        f.parts.push_back(part);
    }
    f.width = f.parts[0].width;
    f.height = f.parts[0].height;
    f.bytes_per_pixel = f.parts[0].bytes_per_pixel;
    return true;
}

// A single-part buffer's image into `f`; false when it is not a whole image.
bool copy_image(ArvBuffer* b, Frame& f) {
    f.width = arv_buffer_get_image_width(b);
    f.height = arv_buffer_get_image_height(b);
    const ArvPixelFormat pf = arv_buffer_get_image_pixel_format(b);
    f.bytes_per_pixel = static_cast<int>((ARV_PIXEL_FORMAT_BIT_PER_PIXEL(pf) + 7) / 8);
    size_t size = 0;
    const auto* data = static_cast<const std::uint8_t*>(arv_buffer_get_data(b, &size));
    const auto expected = static_cast<size_t>(f.width) * static_cast<size_t>(f.height) *
                          static_cast<size_t>(f.bytes_per_pixel);
    if (!data || size < expected) return false;
    f.data.assign(data, data + expected);
    return true;
}

// GigE Vision grants one application the control channel. After a crash the dead process
// holds it until its heartbeat expires: Aravis then opens the device without control, and
// every register write is refused (access-denied). Try to take it until `wait_ms` have passed.
std::string take_control(ArvCamera* camera, int wait_ms) {
    if (!arv_camera_is_gv_device(camera)) return {};
    auto* gv = ARV_GV_DEVICE(arv_camera_get_device(camera));
    const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(wait_ms);
    std::string why = "held by another application";
    while (!arv_gv_device_is_controller(gv)) {
        GError* e = nullptr;
        if (arv_gv_device_take_control(gv, &e)) break;
        if (e) why = take(e);
        if (std::chrono::steady_clock::now() >= until)
            return "control channel not granted after " + std::to_string(wait_ms) + " ms (" + why +
                   "; another application holds it, or a crashed one until its heartbeat "
                   "expires)";
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
    return {};
}

}  // namespace

struct Camera::Impl {
    CameraConfig config;
    ArvCamera* camera = nullptr;
    ArvStream* stream = nullptr;
    std::string name;
    std::atomic<bool> control_lost{false};
    gulong lost_handler = 0;
    bool streaming = false;
    int consecutive_timeouts = 0;
    // The acquisition's start: when AcquisitionStart was sent, whether a complete frame has
    // come since. (Aravis's missing-frame count is no evidence here: block ids may skip across
    // a stop and a start, a frame aborted by the stop having used one.)
    std::int64_t start_sent_ns = 0;
    bool complete_seen = false;
    int stale_now = 0;  // buffers of the acquisition before, set aside in this one

    ~Impl() {
        if (streaming && camera) {
            GError* e = nullptr;
            arv_camera_stop_acquisition(camera, &e);
            g_clear_error(&e);
        }
        if (stream) g_object_unref(stream);
        if (camera) {
            if (lost_handler)
                g_signal_handler_disconnect(arv_camera_get_device(camera), lost_handler);
            g_object_unref(camera);
        }
    }
};

Camera::Camera(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Camera::~Camera() = default;

core::Result<std::unique_ptr<Camera>> Camera::open(const CameraConfig& c) {
    if (c.n_buffers < 2 || c.n_buffers > 1024)
        return core::make_error("camera: n_buffers must be in [2, 1024]");
    if (c.timeout_ms < 1) return core::make_error("camera: timeout_ms must be >= 1");
    auto impl = std::make_unique<Impl>();
    impl->config = c;
    impl->name = c.id.empty() ? "the first camera" : "camera '" + c.id + "'";
    GError* e = nullptr;
    impl->camera = arv_camera_new(c.id.empty() ? nullptr : c.id.c_str(), &e);
    if (!impl->camera) {
        const std::string why = take(e);
        return core::make_error(impl->name + ": cannot open" + (why.empty() ? "" : ": " + why));
    }
    auto fail = [&](const std::string& what) -> core::Error {
        return core::make_error(impl->name + ": " + what + ": " + take(e));
    };
    if (const auto why = take_control(impl->camera, c.control_wait_ms); !why.empty())
        return core::make_error(impl->name + ": " + why);
    // An acquisition a crashed process left running would carry on into our first scan: the
    // frames (and on a moving axis the scan itself) would start before our AcquisitionStart.
    arv_camera_stop_acquisition(impl->camera, &e);
    g_clear_error(&e);
    ArvDevice* device = arv_camera_get_device(impl->camera);
    impl->lost_handler =
        g_signal_connect(device, "control-lost", G_CALLBACK(+[](ArvDevice*, gpointer flag) {
                             static_cast<std::atomic<bool>*>(flag)->store(true);
                         }),
                         &impl->control_lost);

    if (c.width > 0 && c.height > 0) {
        arv_camera_set_region(impl->camera, c.offset_x, c.offset_y, c.width, c.height, &e);
        if (e) return fail("region " + std::to_string(c.width) + "x" + std::to_string(c.height));
    }
    if (!c.pixel_format.empty()) {
        arv_camera_set_pixel_format_from_string(impl->camera, c.pixel_format.c_str(), &e);
        if (e) return fail("pixel format " + c.pixel_format);
    }
    if (c.trigger == "free") {
        arv_camera_set_acquisition_mode(impl->camera, ARV_ACQUISITION_MODE_CONTINUOUS, &e);
        if (e) return fail("acquisition mode");
        arv_device_set_string_feature_value(device, "TriggerMode", "Off", &e);
        g_clear_error(&e);  // cameras without triggers are free-running anyway
        if (c.frame_rate_hz > 0) {
            arv_camera_set_frame_rate(impl->camera, c.frame_rate_hz, &e);
            if (e) return fail("frame rate " + std::to_string(c.frame_rate_hz));
        }
    } else if (c.trigger == "software" || c.trigger == "external") {
        arv_camera_set_trigger(impl->camera,
                               c.trigger == "software" ? "Software" : c.trigger_source.c_str(), &e);
        if (e) return fail("trigger " + c.trigger);
    } else {
        return core::make_error(impl->name + ": trigger must be free, software or external, not '" +
                                c.trigger + "'");
    }
    if (c.exposure_us > 0) {
        arv_camera_set_exposure_time(impl->camera, c.exposure_us, &e);
        if (e) return fail("exposure " + std::to_string(c.exposure_us) + " us");
    }
    for (const auto& [feature, value] : c.features) {
        const std::string s = feature + "=" + value;
        if (!arv_device_set_features_from_string(device, s.c_str(), &e) || e)
            return fail("feature " + s);
    }
    if (arv_camera_is_gv_device(impl->camera) && c.packet_size > 0) {
        arv_camera_gv_set_packet_size(impl->camera, c.packet_size, &e);
        if (e) return fail("packet size " + std::to_string(c.packet_size));
    }
    impl->stream = arv_camera_create_stream(impl->camera, nullptr, nullptr, &e);
    if (!impl->stream) return fail("cannot create the stream");
    if (ARV_IS_GV_STREAM(impl->stream))
        g_object_set(impl->stream, "packet-resend",
                     c.packet_resend ? ARV_GV_STREAM_PACKET_RESEND_ALWAYS
                                     : ARV_GV_STREAM_PACKET_RESEND_NEVER,
                     nullptr);
    const guint payload = arv_camera_get_payload(impl->camera, &e);
    if (e || payload == 0) return fail("payload size");
    for (int i = 0; i < c.n_buffers; ++i)
        arv_stream_push_buffer(impl->stream, arv_buffer_new(payload, nullptr));
    const char* vendor = arv_camera_get_vendor_name(impl->camera, nullptr);
    const char* model = arv_camera_get_model_name(impl->camera, nullptr);
    const char* serial = arv_camera_get_device_serial_number(impl->camera, nullptr);
    impl->name = std::string(vendor ? vendor : "?") + " " + (model ? model : "?") + " serial " +
                 (serial ? serial : "?") + (c.id.empty() ? "" : " (" + c.id + ")");
    return std::unique_ptr<Camera>(new Camera(std::move(impl)));
}

core::Result<void> Camera::start() {
    // Frames left over from the last acquisition (completed after its scan ended) belong to
    // another scan, with timestamps from before this one: back to the pool, unread.
    while (ArvBuffer* b = arv_stream_try_pop_buffer(impl_->stream))
        arv_stream_push_buffer(impl_->stream, b);
    GError* e = nullptr;
    start_ = {};
    impl_->complete_seen = false;
    impl_->stale_now = 0;
    impl_->start_sent_ns = core::realtime_ns();
    arv_camera_start_acquisition(impl_->camera, &e);
    if (e) return core::make_error(impl_->name + ": cannot start acquisition: " + take(e));
    impl_->streaming = true;
    impl_->consecutive_timeouts = 0;
    return {};
}

void Camera::stop() {
    if (!impl_->streaming) return;
    // A lost camera is not asked: each unanswered GVCP command costs Aravis 5 × 500 ms.
    if (lost()) {
        impl_->streaming = false;
        return;
    }
    GError* e = nullptr;
    arv_camera_stop_acquisition(impl_->camera, &e);
    g_clear_error(&e);
    impl_->streaming = false;
}

bool Camera::in_control() const {
    if (lost()) return false;
    if (!arv_camera_is_gv_device(impl_->camera)) return true;
    // GigE Vision's control channel privilege register: a device that restarted (power, a
    // firmware reset) has forgotten us, though Aravis's heartbeat may not have noticed yet.
    constexpr guint64 kControlChannelPrivilege = 0x0A00;
    constexpr guint32 kControlOrExclusive = 0x3;
    guint32 value = 0;
    GError* e = nullptr;
    arv_device_read_register(arv_camera_get_device(impl_->camera), kControlChannelPrivilege, &value,
                             &e);
    if (e) {
        g_clear_error(&e);
        return false;
    }
    return (value & kControlOrExclusive) != 0;
}

bool Camera::lost() const {
    return impl_->control_lost.load() || impl_->consecutive_timeouts >= impl_->config.max_timeouts;
}

core::Result<Frame> Camera::next() {
    if (lost()) return core::make_error(impl_->name + ": camera lost");
    for (;;) {
        ArvBuffer* b = arv_stream_timeout_pop_buffer(
            impl_->stream, static_cast<guint64>(impl_->config.timeout_ms) * 1000u);
        arv_stream_get_statistics(impl_->stream, &stats_.completed, &stats_.failures,
                                  &stats_.underruns);
        if (ARV_IS_GV_STREAM(impl_->stream)) {
            auto info = [&](const char* name) {
                return arv_stream_get_info_uint64_by_name(impl_->stream, name);
            };
            stats_.missing_frames = info("n_missing_frames");
            stats_.missing_packets = info("n_missing_packets");
            stats_.resend_requests = info("n_resend_requests");
            stats_.resent_packets = info("n_resent_packets");
        }
        if (!b) {
            ++stats_.timeouts;
            ++impl_->consecutive_timeouts;
            if (lost())
                return core::make_error(impl_->name + ": camera lost (no frame for " +
                                        std::to_string(impl_->consecutive_timeouts) + " × " +
                                        std::to_string(impl_->config.timeout_ms) + " ms" +
                                        (impl_->control_lost ? ", control lost" : "") + ")");
            return core::make_error(impl_->name + ": timeout: no frame within " +
                                    std::to_string(impl_->config.timeout_ms) + " ms");
        }
        impl_->consecutive_timeouts = 0;
        // Aravis stamps a buffer with the host time (CLOCK_REALTIME) of its frame's leader. A
        // complete frame whose leader came before our AcquisitionStart was on its way when the
        // last acquisition stopped: it belongs to that one (another scan, and it would anchor
        // this scan's positions). Only before the first frame of ours, and at most a pool's
        // worth: a wall clock stepped back must not make every frame look old. (An incomplete
        // buffer's stamp may be an older use's: it counts as lost below.)
        const bool complete = arv_buffer_get_status(b) == ARV_BUFFER_STATUS_SUCCESS;
        const auto leader_ns = static_cast<std::int64_t>(arv_buffer_get_system_timestamp(b));
        if (complete && !impl_->complete_seen && leader_ns > 0 &&
            leader_ns < impl_->start_sent_ns && impl_->stale_now < impl_->config.n_buffers) {
            ++stats_.stale;
            ++impl_->stale_now;
            arv_stream_push_buffer(impl_->stream, b);
            continue;
        }
        if (start_.lag_ns < 0)
            start_.lag_ns = (complete && leader_ns > 0 ? leader_ns : core::realtime_ns()) -
                            impl_->start_sent_ns;
        // An incomplete buffer is counted, handed back and never returned.
        auto skip = [&] {
            ++stats_.incomplete;
            if (!impl_->complete_seen) ++start_.lost;
            arv_stream_push_buffer(impl_->stream, b);
        };
        if (!complete) {
            skip();
            continue;
        }
        Frame f;
        f.camera_ns = static_cast<std::int64_t>(arv_buffer_get_timestamp(b));
        const bool whole = arv_buffer_get_payload_type(b) == ARV_BUFFER_PAYLOAD_TYPE_MULTIPART
                               ? copy_parts(b, f)
                               : copy_image(b, f);
        if (!whole) {
            skip();
            continue;
        }
        f.system_ns = core::realtime_ns();
        f.frame_id = arv_buffer_get_frame_id(b);
        arv_stream_push_buffer(impl_->stream, b);
        impl_->complete_seen = true;
        ++stats_.frames;
        return f;
    }
}

core::Result<void> Camera::software_trigger() {
    GError* e = nullptr;
    arv_camera_software_trigger(impl_->camera, &e);
    if (e) return core::make_error(impl_->name + ": software trigger: " + take(e));
    return {};
}

core::Result<void> Camera::set_exposure_us(double exposure_us) {
    GError* e = nullptr;
    arv_camera_set_exposure_time(impl_->camera, exposure_us, &e);
    if (e) return core::make_error(impl_->name + ": exposure: " + take(e));
    return {};
}

std::string Camera::description() const { return impl_->name; }

}  // namespace hotgauge::acquire
