// The source factory and config validation (docs/accelerometer.md, "Configuration").
#include "hotgauge/accel/source.hpp"

#include "hotgauge/accel/iio.hpp"
#include "hotgauge/accel/replay.hpp"
#include "hotgauge/accel/udp.hpp"

namespace hotgauge::accel {

const char* to_string(AccelSourceKind kind) {
    switch (kind) {
        case AccelSourceKind::udp:
            return "udp";
        case AccelSourceKind::iio:
            return "iio";
        case AccelSourceKind::recording:
            return "recording";
    }
    return "?";
}

core::Result<AccelSourceKind> parse_accel_source_kind(std::string_view text) {
    for (auto k : {AccelSourceKind::udp, AccelSourceKind::iio, AccelSourceKind::recording})
        if (text == to_string(k)) return k;
    return core::make_error("kind: unknown accelerometer source '" + std::string(text) +
                            "', expected udp, iio or recording");
}

core::Result<void> validate(const AccelSourceConfig& c) {
    switch (c.kind) {
        case AccelSourceKind::udp:
            if (auto hp = parse_host_port(c.udp.bind, "udp.bind"); !hp) return hp.error();
            if (c.udp.receive_buffer_bytes < 0)
                return core::make_error("udp.receive_buffer_bytes: must be ≥ 0, found " +
                                        std::to_string(c.udp.receive_buffer_bytes));
            return {};
        case AccelSourceKind::iio:
            if (c.iio.device_dir.empty())
                return core::make_error(
                    "iio.device_dir: empty, expected a sysfs device directory such as "
                    "/sys/bus/iio/devices/iio:device0");
            if (c.iio.buffer_path.empty())
                return core::make_error(
                    "iio.buffer_path: empty, expected the buffer device such as /dev/iio:device0");
            if (c.iio.buffer_length <= 0)
                return core::make_error("iio.buffer_length: must be positive, found " +
                                        std::to_string(c.iio.buffer_length));
            return {};
        case AccelSourceKind::recording:
            if (c.recording.path.empty())
                return core::make_error("recording.path: empty, expected a recording folder");
            if (c.recording.face.empty())
                return core::make_error("recording.face: empty, expected a face name such as top");
            return {};
    }
    return core::make_error("kind: invalid value " + std::to_string(static_cast<int>(c.kind)));
}

core::Result<std::unique_ptr<AccelSource>> make_accel_source(const AccelSourceConfig& c,
                                                             AccelRing& ring) {
    if (auto r = validate(c); !r) return r.error();
    std::unique_ptr<AccelSource> s;
    switch (c.kind) {
        case AccelSourceKind::udp:
            s = std::make_unique<UdpAccelReceiver>(c.udp, ring);
            break;
        case AccelSourceKind::iio:
            s = std::make_unique<IioAccelSource>(c.iio, ring);
            break;
        case AccelSourceKind::recording:
            s = std::make_unique<RecordingAccelSource>(c.recording, ring);
            break;
    }
    return s;
}

}  // namespace hotgauge::accel
