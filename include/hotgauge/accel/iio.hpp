#pragma once
// The `iio` accelerometer source: a Linux IIO buffered device (ADXL355 class). The channel
// layout comes from sysfs (DIR/scan_elements/*_en, *_index, *_type; DIR/in_accel_scale,
// sampling_frequency), the records from the buffer character device (/dev/iio:deviceN).
// Kernel reference: Documentation/ABI/testing/sysfs-bus-iio ("scan_elements") and
// Documentation/driver-api/iio/buffers.rst; docs/accelerometer.md ("iio").
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "hotgauge/accel/ring.hpp"
#include "hotgauge/accel/source.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::accel {

// A scan element's storage as sysfs declares it: "[be|le]:[s|u]bits/storagebits[Xrepeat]>>shift",
// e.g. "le:s20/32>>4" (20 significant bits, stored in 32, shifted left by 4).
struct IioScanType {
    bool big_endian = false;
    bool is_signed = true;
    unsigned real_bits = 0;     // significant bits
    unsigned storage_bits = 0;  // 8, 16, 32 or 64
    unsigned repeat = 1;        // elements of this channel in one scan
    unsigned shift = 0;         // right shift before masking to real_bits
};

// Parses a _type string; the Error says what is malformed (the caller prefixes the file).
core::Result<IioScanType> parse_iio_scan_type(std::string_view text);

// The value of one element: storage bytes in the declared byte order, shifted right, masked to
// real_bits and sign-extended when signed. `element` holds at least storage_bits/8 bytes.
std::int64_t iio_element_value(const IioScanType& type, const std::uint8_t* element);

struct IioChannel {
    std::string name;  // "in_accel_x", "in_timestamp", any other enabled scan element
    int index = 0;     // scan index
    IioScanType type;
    std::size_t offset_bytes = 0;  // position in a scan record
};

// How one scan record of the buffer is laid out and what it means.
struct IioLayout {
    std::vector<IioChannel> channels;      // the enabled scan elements in index order
    std::size_t record_bytes = 0;          // padded to the largest element's storage size
    std::array<std::size_t, 3> accel{};    // positions in `channels` of in_accel_x, _y, _z
    std::optional<std::size_t> timestamp;  // position of in_timestamp (ns), if enabled
    std::array<double, 3> scale_mps2{};    // m/s² per LSB, x y z
    std::array<double, 3> offset_lsb{};    // added to the raw value before scaling
    std::optional<double> sampling_frequency_hz;
};

// Discovers the layout from a sysfs device directory. Errors name the file: a missing or
// malformed _type/_index/_en, a missing accelerometer channel or scale, no way to time samples
// (neither an enabled timestamp channel nor a sampling frequency).
core::Result<IioLayout> read_iio_layout(const std::filesystem::path& device_dir);

// Decodes whole records (records.size() a multiple of record_bytes). Times come from the
// timestamp channel; without one, record k of the stream (k = first_index + i) is at
// t0_ns + round(k · 1e9 / sampling_frequency_hz).
std::vector<AccelSample> decode_iio_records(const IioLayout& layout,
                                            std::span<const std::uint8_t> records,
                                            std::int64_t t0_ns, std::uint64_t first_index);

// Enables in_accel_{x,y,z} (and in_timestamp when present), sets buffer/length and enables the
// buffer, through sysfs writes. Needs the permissions the device nodes have (root or a udev
// rule). Errors name the file written.
core::Result<void> enable_iio_buffer(const std::filesystem::path& device_dir, int buffer_length);
core::Result<void> disable_iio_buffer(const std::filesystem::path& device_dir);

// Reads records from IioSourceConfig::buffer_path into the ring. A regular file is read to its
// end (state finished): captured buffers replay that way, and the tests use it.
// Thread safety: start/stop from one thread; status/layout from any.
class IioAccelSource final : public AccelSource {
  public:
    IioAccelSource(IioSourceConfig config, AccelRing& ring);
    ~IioAccelSource() override;
    IioAccelSource(const IioAccelSource&) = delete;
    IioAccelSource& operator=(const IioAccelSource&) = delete;

    core::Result<void> start() override;
    void stop() override;
    AccelSourceStatus status() const override;
    IioLayout layout() const;

  private:
    void run();
    void finish(AccelSourceState state, const std::string& error);

    IioSourceConfig config_;
    AccelRing& ring_;
    int fd_ = -1;
    int wake_fd_ = -1;
    std::thread thread_;
    std::atomic<bool> stop_{false};
    bool enabled_buffer_ = false;

    mutable std::mutex mutex_;  // guards everything below
    IioLayout layout_;
    std::int64_t t0_ns_ = 0;
    AccelSourceStatus status_;
};

}  // namespace hotgauge::accel
