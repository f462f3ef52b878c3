// Linux IIO buffered accelerometers (docs/accelerometer.md, "iio").
#include "hotgauge/accel/iio.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cassert>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <ctime>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <utility>

#include "log.hpp"
#include "worker.hpp"

namespace fs = std::filesystem;

namespace hotgauge::accel {

namespace {

constexpr std::array<const char*, 3> kAccelChannels = {"in_accel_x", "in_accel_y", "in_accel_z"};
constexpr const char* kTimestampChannel = "in_timestamp";

std::string trim(std::string s) {
    const auto not_space = [](unsigned char c) { return !std::isspace(c); };
    s.erase(s.begin(), std::find_if(s.begin(), s.end(), not_space));
    s.erase(std::find_if(s.rbegin(), s.rend(), not_space).base(), s.end());
    return s;
}

// A sysfs attribute: one line of text. nullopt when the file does not exist.
core::Result<std::optional<std::string>> read_attr(const fs::path& p) {
    std::error_code ec;
    if (!fs::exists(p, ec)) return std::optional<std::string>();
    std::ifstream in(p);
    if (!in) return core::make_error(p.string() + ": cannot open: " + std::strerror(errno));
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) return core::make_error(p.string() + ": read error");
    return std::optional<std::string>(trim(std::move(text)));
}

core::Result<std::string> read_required(const fs::path& p, const std::string& why_needed) {
    auto text = read_attr(p);
    if (!text) return text.error();
    if (!*text) return core::make_error(p.string() + ": missing" + why_needed);
    return std::move(**text);
}

core::Result<long long> parse_int(const fs::path& p, const std::string& text) {
    long long v = 0;
    const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (text.empty() || ec != std::errc() || end != text.data() + text.size())
        return core::make_error(p.string() + ": expected an integer, found '" + text + "'");
    return v;
}

core::Result<double> parse_real(const fs::path& p, const std::string& text) {
    // sysfs writes fixed-point decimals ("0.000038245"); strtod in the C locale reads them.
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(v))
        return core::make_error(p.string() + ": expected a finite number, found '" + text + "'");
    return v;
}

// Optional number: first existing file wins.
core::Result<std::optional<double>> read_real_any(const std::vector<fs::path>& candidates) {
    for (const auto& p : candidates) {
        auto text = read_attr(p);
        if (!text) return text.error();
        if (!*text) continue;
        auto v = parse_real(p, **text);
        if (!v) return v.error();
        return std::optional<double>(*v);
    }
    return std::optional<double>();
}

core::Result<void> write_attr(const fs::path& p, const std::string& value) {
    const int fd = ::open(p.c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
    if (fd < 0)
        return core::make_error(p.string() + ": cannot open for writing: " + std::strerror(errno));
    const ssize_t n = ::write(fd, value.data(), value.size());
    const int write_errno = errno;
    const bool closed = ::close(fd) == 0;  // sysfs may report the error at close
    if (n != static_cast<ssize_t>(value.size()) || !closed)
        return core::make_error(p.string() + ": cannot write '" + value +
                                "': " + std::strerror(n < 0 ? write_errno : errno));
    return {};
}

// Unsigned decimal at s[i...]; advances i.
bool take_uint(std::string_view s, std::size_t& i, unsigned& out) {
    const auto [end, ec] = std::from_chars(s.data() + i, s.data() + s.size(), out);
    if (ec != std::errc()) return false;
    i = static_cast<std::size_t>(end - s.data());
    return true;
}

}  // namespace

core::Result<IioScanType> parse_iio_scan_type(std::string_view s) {
    const auto bad = [&](const std::string& why) {
        return core::make_error("malformed scan type '" + std::string(s) + "' (" + why +
                                "; expected like le:s20/32>>4)");
    };
    IioScanType t;
    if (s.size() < 3 || s[2] != ':') return bad("no byte order");
    if (s.substr(0, 2) == "le")
        t.big_endian = false;
    else if (s.substr(0, 2) == "be")
        t.big_endian = true;
    else
        return bad("byte order is not le or be");
    std::size_t i = 3;
    if (i >= s.size()) return bad("no sign");
    // Upper case (S, U) marks a fully defined value in newer kernels; same layout.
    const char sign = s[i++];
    if (sign == 's' || sign == 'S')
        t.is_signed = true;
    else if (sign == 'u' || sign == 'U')
        t.is_signed = false;
    else
        return bad("sign is not s or u");
    if (!take_uint(s, i, t.real_bits)) return bad("no bit count");
    if (i >= s.size() || s[i++] != '/') return bad("no '/' after the bit count");
    if (!take_uint(s, i, t.storage_bits)) return bad("no storage size");
    if (i < s.size() && s[i] == 'X') {
        ++i;
        if (!take_uint(s, i, t.repeat) || t.repeat == 0) return bad("bad repeat count");
    }
    if (s.substr(i, 2) != ">>") return bad("no '>>' shift");
    i += 2;
    if (!take_uint(s, i, t.shift)) return bad("no shift");
    if (i != s.size()) return bad("trailing characters");
    if (t.storage_bits != 8 && t.storage_bits != 16 && t.storage_bits != 32 && t.storage_bits != 64)
        return bad("storage size must be 8, 16, 32 or 64 bits");
    if (t.real_bits == 0 || t.real_bits > t.storage_bits)
        return bad("bit count must be 1..storage size");
    if (t.shift > t.storage_bits || t.shift + t.real_bits > t.storage_bits)
        return bad("shift + bits exceed the storage size");
    if (t.repeat > 256) return bad("repeat count above 256");
    return t;
}

std::int64_t iio_element_value(const IioScanType& t, const std::uint8_t* p) {
    const unsigned bytes = t.storage_bits / 8;
    std::uint64_t raw = 0;
    for (unsigned i = 0; i < bytes; ++i) {
        const unsigned byte_index = t.big_endian ? i : bytes - 1 - i;  // most significant first
        raw = (raw << 8) | p[byte_index];
    }
    raw >>= t.shift;
    if (t.real_bits < 64) {
        const std::uint64_t mask = (std::uint64_t{1} << t.real_bits) - 1;
        raw &= mask;
        if (t.is_signed && ((raw >> (t.real_bits - 1)) & 1u) != 0) raw |= ~mask;  // sign-extend
    }
    return static_cast<std::int64_t>(raw);
}

namespace {

// The scan elements' names ("in_accel_x" for in_accel_x_en), sorted. Every enabled scan element
// occupies room in a record, whether we use it or not.
core::Result<std::vector<std::string>> list_scan_elements(const fs::path& scan) {
    std::error_code ec;
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(scan, ec)) {
        const std::string file = entry.path().filename().string();
        if (file.size() > 3 && file.ends_with("_en"))
            names.push_back(file.substr(0, file.size() - 3));
    }
    if (ec) return core::make_error(scan.string() + ": cannot list: " + ec.message());
    std::sort(names.begin(), names.end());
    return names;
}

// One scan element: nullopt when it is not enabled. `by_index` holds the enabled ones' indices
// so far (name by index): two elements on one index are an error.
core::Result<std::optional<IioChannel>> read_scan_element(const fs::path& scan,
                                                          const std::string& name,
                                                          std::map<int, std::string>& by_index) {
    const fs::path en_path = scan / (name + "_en");
    auto en = read_required(en_path, "");
    if (!en) return en.error();
    if (*en != "0" && *en != "1")
        return core::make_error(en_path.string() + ": expected 0 or 1, found '" + *en + "'");
    if (*en == "0") return std::optional<IioChannel>();

    const fs::path index_path = scan / (name + "_index");
    auto index_text = read_required(index_path, " (every scan element has an index)");
    if (!index_text) return index_text.error();
    auto index = parse_int(index_path, *index_text);
    if (!index) return index.error();
    if (*index < 0 || *index > 1'000'000)
        return core::make_error(index_path.string() + ": index " + *index_text + " out of range");
    if (auto [it, fresh] = by_index.emplace(static_cast<int>(*index), name); !fresh)
        return core::make_error(index_path.string() + ": index " + *index_text +
                                " is also the index of " + it->second);

    const fs::path type_path = scan / (name + "_type");
    auto type_text = read_required(type_path, " (every scan element has a type)");
    if (!type_text) return type_text.error();
    auto type = parse_iio_scan_type(*type_text);
    if (!type) return core::make_error(type_path.string() + ": " + type.error().message);

    return std::optional<IioChannel>(IioChannel{name, static_cast<int>(*index), *type, 0});
}

// Each element aligned to its own storage size, in index order; the record padded to the
// largest storage size (the kernel's iio_compute_scan_bytes, industrialio-buffer.c).
void place_channels(IioLayout& layout) {
    std::size_t offset = 0, largest = 1;
    for (auto& ch : layout.channels) {
        const std::size_t bytes = ch.type.storage_bits / 8;
        offset = (offset + bytes - 1) / bytes * bytes;
        ch.offset_bytes = offset;
        offset += bytes * ch.type.repeat;
        largest = std::max(largest, bytes);
    }
    layout.record_bytes = (offset + largest - 1) / largest * largest;
}

// The position in layout.channels of the enabled element `name`.
std::optional<std::size_t> channel_position(const IioLayout& layout, const std::string& name) {
    for (std::size_t i = 0; i < layout.channels.size(); ++i)
        if (layout.channels[i].name == name) return i;
    return std::nullopt;
}

// Accelerometer axis `axis` (x, y, z): enabled, one value per scan, with its scale (its own or
// the shared in_accel_scale) and offset.
core::Result<void> read_accel_axis(const fs::path& dir, const fs::path& scan, std::size_t axis,
                                   IioLayout& layout) {
    std::error_code ec;
    const std::string name = kAccelChannels[axis];
    const fs::path en_path = scan / (name + "_en");
    if (!fs::exists(en_path, ec))
        return core::make_error(en_path.string() + ": missing (the device has no " + name +
                                " channel)");
    const auto pos = channel_position(layout, name);
    if (!pos)
        return core::make_error(en_path.string() + ": " + name +
                                " is not enabled (0); enable_iio_buffer enables it");
    const auto& t = layout.channels[*pos].type;
    if (t.repeat != 1)
        return core::make_error((scan / (name + "_type")).string() + ": repeat " +
                                std::to_string(t.repeat) + ", expected one value per scan");
    layout.accel[axis] = *pos;

    auto scale = read_real_any({dir / (name + "_scale"), dir / "in_accel_scale"});
    if (!scale) return scale.error();
    if (!*scale)
        return core::make_error((dir / "in_accel_scale").string() + ": missing (nor is there " +
                                name + "_scale): cannot convert to m/s²");
    if (**scale <= 0.0)
        return core::make_error((dir / "in_accel_scale").string() +
                                ": scale must be positive, found " + std::to_string(**scale));
    layout.scale_mps2[axis] = **scale;
    auto off = read_real_any({dir / (name + "_offset"), dir / "in_accel_offset"});
    if (!off) return off.error();
    layout.offset_lsb[axis] = off->value_or(0.0);
    return {};
}

// The samples' times: the timestamp channel when enabled, the sampling frequency when there is
// one; at least one of the two.
core::Result<void> read_timing(const fs::path& dir, const fs::path& scan, IioLayout& layout) {
    if (const auto ts = channel_position(layout, kTimestampChannel)) {
        const auto& t = layout.channels[*ts].type;
        if (t.storage_bits != 64 || t.real_bits != 64 || t.repeat != 1)
            return core::make_error((scan / "in_timestamp_type").string() +
                                    ": timestamp must be a 64-bit value in ns");
        layout.timestamp = *ts;
    }
    auto freq = read_real_any({dir / "sampling_frequency", dir / "in_accel_sampling_frequency"});
    if (!freq) return freq.error();
    if (*freq && !(**freq > 0.0))
        return core::make_error((dir / "sampling_frequency").string() +
                                ": sampling frequency must be positive");
    layout.sampling_frequency_hz = *freq;
    if (!layout.timestamp && !layout.sampling_frequency_hz)
        return core::make_error((dir / "sampling_frequency").string() +
                                ": missing, and the timestamp channel is not enabled: there is "
                                "no way to time the samples");
    return {};
}

}  // namespace

core::Result<IioLayout> read_iio_layout(const fs::path& dir) {
    const fs::path scan = dir / "scan_elements";
    std::error_code ec;
    if (!fs::is_directory(scan, ec))
        return core::make_error(scan.string() +
                                ": missing (not an IIO device with a buffer, or the wrong "
                                "sysfs directory)");
    auto names = list_scan_elements(scan);
    if (!names) return names.error();

    IioLayout layout;
    std::map<int, std::string> by_index;
    for (const auto& name : *names) {
        auto channel = read_scan_element(scan, name, by_index);
        if (!channel) return channel.error();
        if (*channel) layout.channels.push_back(std::move(**channel));
    }
    std::sort(layout.channels.begin(), layout.channels.end(),
              [](const IioChannel& a, const IioChannel& b) { return a.index < b.index; });
    place_channels(layout);

    for (std::size_t axis = 0; axis < 3; ++axis)
        if (auto ok = read_accel_axis(dir, scan, axis, layout); !ok) return ok.error();
    if (auto ok = read_timing(dir, scan, layout); !ok) return ok.error();
    return layout;
}

std::vector<AccelSample> decode_iio_records(const IioLayout& layout,
                                            std::span<const std::uint8_t> records,
                                            std::int64_t t0_ns, std::uint64_t first_index) {
    assert(layout.record_bytes > 0 && records.size() % layout.record_bytes == 0);
    const std::size_t n = records.size() / layout.record_bytes;
    std::vector<AccelSample> out(n);
    const double period_ns =
        layout.sampling_frequency_hz ? 1e9 / *layout.sampling_frequency_hz : 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint8_t* rec = records.data() + i * layout.record_bytes;
        float v[3];
        for (std::size_t a = 0; a < 3; ++a) {
            const IioChannel& ch = layout.channels[layout.accel[a]];
            const auto raw = static_cast<double>(iio_element_value(ch.type, rec + ch.offset_bytes));
            v[a] = static_cast<float>((raw + layout.offset_lsb[a]) * layout.scale_mps2[a]);
        }
        std::int64_t t = 0;
        if (layout.timestamp) {
            const IioChannel& ch = layout.channels[*layout.timestamp];
            t = iio_element_value(ch.type, rec + ch.offset_bytes);
        } else {
            t = t0_ns + std::llround(static_cast<double>(first_index + i) * period_ns);
        }
        out[i] = {t, v[0], v[1], v[2]};
    }
    return out;
}

core::Result<void> enable_iio_buffer(const fs::path& dir, int buffer_length) {
    // Scan elements can only change while the buffer is disabled.
    if (auto r = write_attr(dir / "buffer" / "enable", "0"); !r) return r;
    for (const char* name : kAccelChannels)
        if (auto r = write_attr(dir / "scan_elements" / (std::string(name) + "_en"), "1"); !r)
            return r;
    std::error_code ec;
    const fs::path ts = dir / "scan_elements" / "in_timestamp_en";
    if (fs::exists(ts, ec))
        if (auto r = write_attr(ts, "1"); !r) return r;
    if (auto r = write_attr(dir / "buffer" / "length", std::to_string(buffer_length)); !r) return r;
    return write_attr(dir / "buffer" / "enable", "1");
}

core::Result<void> disable_iio_buffer(const fs::path& dir) {
    return write_attr(dir / "buffer" / "enable", "0");
}

// ---------------------------------------------------------------------------------------------

IioAccelSource::IioAccelSource(IioSourceConfig config, AccelRing& ring)
    : config_(std::move(config)), ring_(ring) {}

IioAccelSource::~IioAccelSource() { stop(); }

core::Result<void> IioAccelSource::start() {
    if (thread_.joinable()) return core::make_error("iio source: already started");
    if (config_.enable_buffer) {
        if (auto r = enable_iio_buffer(config_.device_dir, config_.buffer_length); !r) return r;
        enabled_buffer_ = true;
    }
    auto layout = read_iio_layout(config_.device_dir);
    if (!layout) {
        stop();
        return layout.error();
    }
    fd_ = ::open(config_.buffer_path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd_ < 0) {
        const auto err = core::make_error(config_.buffer_path.string() +
                                          ": cannot open: " + std::strerror(errno));
        stop();
        return err;
    }
    wake_fd_ = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
    if (wake_fd_ < 0) {
        const auto err =
            core::make_error("iio source: eventfd: " + std::string(std::strerror(errno)));
        stop();
        return err;
    }

    std::int64_t t0 = 0;
    if (config_.start_time_ns) {
        t0 = *config_.start_time_ns;
    } else {
        timespec ts{};
        ::clock_gettime(CLOCK_REALTIME, &ts);
        t0 = static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
    }

    AccelSourceStatus st;
    st.state = AccelSourceState::running;
    std::ostringstream desc;
    desc << "record of " << layout->record_bytes << " bytes:";
    for (const auto& ch : layout->channels)
        desc << ' ' << ch.name << '@' << ch.offset_bytes << (ch.type.big_endian ? " be:" : " le:")
             << (ch.type.is_signed ? 's' : 'u') << ch.type.real_bits << '/' << ch.type.storage_bits
             << ">>" << ch.type.shift << ';';
    st.notes.push_back(desc.str());
    if (!layout->timestamp) {
        st.notes.push_back(
            "no timestamp channel: sample times synthesised from sampling_frequency " +
            std::to_string(*layout->sampling_frequency_hz) + " Hz from " + std::to_string(t0) +
            " ns; clock drift and samples lost in the kernel are invisible");
    }
    for (const auto& note : st.notes)
        detail::log().info("iio {}: {}", config_.buffer_path.string(), note);
    {
        std::lock_guard lock(mutex_);
        layout_ = std::move(*layout);
        t0_ns_ = t0;
        status_ = std::move(st);
    }
    stop_ = false;
    thread_ = std::thread([this] { run(); });
    return {};
}

void IioAccelSource::stop() {
    detail::stop_worker(thread_, stop_, wake_fd_, fd_);
    if (enabled_buffer_) {
        enabled_buffer_ = false;
        if (auto r = disable_iio_buffer(config_.device_dir); !r)
            detail::log().warn("iio: {}", r.error().message);
    }
    std::lock_guard lock(mutex_);
    if (status_.state == AccelSourceState::running) status_.state = AccelSourceState::stopped;
}

void IioAccelSource::finish(AccelSourceState state, const std::string& error) {
    std::lock_guard lock(mutex_);
    status_.state = state;
    if (!error.empty()) {
        status_.error = config_.buffer_path.string() + ": " + error;
        detail::log().error("iio: {}", status_.error);
    }
}

void IioAccelSource::run() {
    const std::size_t record = layout_.record_bytes;  // layout_ is fixed while running
    std::vector<std::uint8_t> pending;                // bytes of an incomplete record
    std::vector<std::uint8_t> chunk(std::max<std::size_t>(record, 1) * 1024);
    std::uint64_t index = 0;
    while (!stop_) {
        pollfd fds[2] = {{fd_, POLLIN, 0}, {wake_fd_, POLLIN, 0}};
        const int r = ::poll(fds, 2, 500);  // the timeout only bounds a missed wake-up
        if (r < 0) {
            if (errno == EINTR) continue;
            return finish(AccelSourceState::failed, std::string("poll: ") + std::strerror(errno));
        }
        if (fds[1].revents != 0) break;
        if (fds[0].revents == 0) continue;
        const ssize_t n = ::read(fd_, chunk.data(), chunk.size());
        if (n < 0) {
            if (errno == EINTR || errno == EAGAIN || errno == EWOULDBLOCK) continue;
            return finish(AccelSourceState::failed, std::string("read: ") + std::strerror(errno));
        }
        if (n == 0) {  // end of a regular file
            if (!pending.empty()) {
                detail::log().warn("iio {}: {} trailing bytes are not a whole {}-byte record",
                                   config_.buffer_path.string(), pending.size(), record);
                std::lock_guard lock(mutex_);
                ++status_.rejected;
            }
            return finish(AccelSourceState::finished, "");
        }
        pending.insert(pending.end(), chunk.begin(), chunk.begin() + n);
        const std::size_t whole = pending.size() / record * record;
        if (whole == 0) continue;
        const auto samples = decode_iio_records(
            layout_, std::span<const std::uint8_t>(pending.data(), whole), t0_ns_, index);
        index += samples.size();
        pending.erase(pending.begin(), pending.begin() + static_cast<std::ptrdiff_t>(whole));
        ring_.push(samples);
        std::lock_guard lock(mutex_);
        status_.samples += samples.size();
    }
}

AccelSourceStatus IioAccelSource::status() const {
    std::lock_guard lock(mutex_);
    return status_;
}

IioLayout IioAccelSource::layout() const {
    std::lock_guard lock(mutex_);
    return layout_;
}

}  // namespace hotgauge::accel
