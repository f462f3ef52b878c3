// PPF model files (docs/model-file.md): magic, format version, body size, body, FNV-1a 64
// checksum. Numbers are little-endian whatever the host; floats are stored as their bit patterns,
// so a round trip is bit-exact.
#include "hotgauge/model/model_io.hpp"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <system_error>
#include <vector>

#include "hotgauge/io/bytes.hpp"
#include "hotgauge/io/checksum.hpp"

namespace hotgauge::model {
namespace {

namespace fs = std::filesystem;
using core::make_error;
using core::Result;
using match::Model;

// "\r\n" after a NUL: a transfer in text mode or through a line-ending filter changes it.
constexpr std::array<unsigned char, 8> kMagic = {'H', 'G', 'P', 'P', 'F', 0, '\r', '\n'};
constexpr std::size_t kHeaderBytes = 8 + 4 + 8;  // magic, version, body size
constexpr std::size_t kChecksumBytes = 8;

class Writer {
  public:
    std::vector<unsigned char> bytes;

    void u8(std::uint8_t v) { bytes.push_back(v); }
    void u32(std::uint32_t v) {
        for (int i = 0; i < 4; ++i) bytes.push_back(static_cast<unsigned char>(v >> (8 * i)));
    }
    void u64(std::uint64_t v) {
        for (int i = 0; i < 8; ++i) bytes.push_back(static_cast<unsigned char>(v >> (8 * i)));
    }
    void i32(std::int32_t v) { u32(static_cast<std::uint32_t>(v)); }
    void f32(float v) { u32(std::bit_cast<std::uint32_t>(v)); }
    void f64(double v) { u64(std::bit_cast<std::uint64_t>(v)); }
    void str(const std::string& s) {
        u64(s.size());
        bytes.insert(bytes.end(), s.begin(), s.end());
    }
    void vec3s(const std::vector<Eigen::Vector3f>& v) {
        u64(v.size());
        for (const Eigen::Vector3f& p : v) {
            f32(p.x());
            f32(p.y());
            f32(p.z());
        }
    }
    void u32s(const std::vector<std::uint32_t>& v) {
        u64(v.size());
        for (std::uint32_t x : v) u32(x);
    }
};

// Bounds-checked reading of the body. The first failure is kept in `error`; later reads return
// zeros, so the caller checks once per group of fields.
class Reader {
  public:
    Reader(const unsigned char* data, std::size_t size, std::size_t pos)
        : data_(data), size_(size), pos_(pos) {}

    std::string error;

    bool ok() const { return error.empty(); }
    std::size_t pos() const { return pos_; }

    std::uint8_t u8(const char* what) {
        if (!take(1, what)) return 0;
        return data_[pos_++];
    }
    std::uint32_t u32(const char* what) {
        if (!take(4, what)) return 0;
        std::uint32_t v = 0;
        for (int i = 0; i < 4; ++i) v |= std::uint32_t{data_[pos_++]} << (8 * i);
        return v;
    }
    std::uint64_t u64(const char* what) {
        if (!take(8, what)) return 0;
        std::uint64_t v = 0;
        for (int i = 0; i < 8; ++i) v |= std::uint64_t{data_[pos_++]} << (8 * i);
        return v;
    }
    std::int32_t i32(const char* what) { return static_cast<std::int32_t>(u32(what)); }
    float f32(const char* what) { return std::bit_cast<float>(u32(what)); }
    double f64(const char* what) { return std::bit_cast<double>(u64(what)); }
    bool flag(const char* what) {
        const std::uint8_t v = u8(what);
        if (ok() && v > 1) fail(std::string(what) + ": flag byte " + std::to_string(v));
        return v == 1;
    }
    // An element count, checked against the bytes left: a corrupt count is an error, never a
    // huge allocation.
    std::size_t count(const char* what, std::size_t element_bytes) {
        const std::uint64_t n = u64(what);
        if (!ok()) return 0;
        const std::size_t left = size_ - pos_;
        if (n > left / element_bytes) {
            fail(std::string(what) + ": count " + std::to_string(n) + " needs more than the " +
                 std::to_string(left) + " bytes left");
            return 0;
        }
        return static_cast<std::size_t>(n);
    }
    std::string str(const char* what) {
        const std::size_t n = count(what, 1);
        if (!ok()) return {};
        std::string s(reinterpret_cast<const char*>(data_ + pos_), n);
        pos_ += n;
        return s;
    }
    std::vector<Eigen::Vector3f> vec3s(const char* what) {
        std::vector<Eigen::Vector3f> v(count(what, 12));
        for (Eigen::Vector3f& p : v) {
            const float x = f32(what), y = f32(what), z = f32(what);
            p = {x, y, z};
        }
        return v;
    }
    std::vector<std::uint32_t> u32s(const char* what) {
        std::vector<std::uint32_t> v(count(what, 4));
        for (std::uint32_t& x : v) x = u32(what);
        return v;
    }

  private:
    bool take(std::size_t n, const char* what) {
        if (!ok()) return false;
        if (size_ - pos_ < n) {
            fail(std::string(what) + ": ends early");
            return false;
        }
        return true;
    }
    void fail(std::string message) {
        if (ok()) error = "at byte " + std::to_string(pos_) + ", " + std::move(message);
    }

    const unsigned char* data_;
    std::size_t size_;
    std::size_t pos_;
};

std::vector<unsigned char> serialize(const Model& m) {
    Writer w;
    w.bytes.assign(kMagic.begin(), kMagic.end());
    w.u32(kModelFormatVersion);
    w.u64(0);  // body size, patched below
    w.str(m.name);
    w.str(m.source);
    w.f64(m.config.sampling_mm);
    w.f64(m.config.distance_step_mm);
    w.i32(m.config.angle_bins);
    w.i32(m.config.alpha_bins);
    w.u8(m.axisymmetric ? 1 : 0);
    w.f64(m.diameter_mm);
    w.f64(m.step_mm);
    w.vec3s(m.points);
    w.vec3s(m.normals);
    w.u32s(m.refs);
    w.u64(m.profile.size());
    for (const auto& s : m.profile) {
        w.u8(s.wall ? 1 : 0);
        w.f64(s.r0);
        w.f64(s.z0);
        w.f64(s.r1);
        w.f64(s.z1);
    }
    w.vec3s(m.dense_points);
    w.vec3s(m.dense_normals);
    w.u32s(m.key_begin);
    w.u64(m.entries.size());
    for (const Model::Entry& e : m.entries) {
        w.u32(e.ref);
        w.f32(e.alpha);
    }
    const std::uint64_t body = w.bytes.size() - kHeaderBytes;
    for (int i = 0; i < 8; ++i) w.bytes[12 + i] = static_cast<unsigned char>(body >> (8 * i));
    w.u64(io::fnv1a64(w.bytes.data(), w.bytes.size()));
    return w.bytes;
}

// The body after the header; `r` has checked nothing but bounds.
Model deserialize(Reader& r) {
    Model m;
    m.name = r.str("name");
    m.source = r.str("source");
    m.config.sampling_mm = r.f64("config.sampling_mm");
    m.config.distance_step_mm = r.f64("config.distance_step_mm");
    m.config.angle_bins = r.i32("config.angle_bins");
    m.config.alpha_bins = r.i32("config.alpha_bins");
    m.axisymmetric = r.flag("axisymmetric");
    m.diameter_mm = r.f64("diameter_mm");
    m.step_mm = r.f64("step_mm");
    m.points = r.vec3s("points");
    m.normals = r.vec3s("normals");
    m.refs = r.u32s("refs");
    m.profile.resize(r.count("profile", 33));
    for (auto& s : m.profile) {
        s.wall = r.flag("profile");
        s.r0 = r.f64("profile");
        s.z0 = r.f64("profile");
        s.r1 = r.f64("profile");
        s.z1 = r.f64("profile");
    }
    m.dense_points = r.vec3s("dense_points");
    m.dense_normals = r.vec3s("dense_normals");
    m.key_begin = r.u32s("key_begin");
    m.entries.resize(r.count("entries", 8));
    for (Model::Entry& e : m.entries) {
        e.ref = r.u32("entries");
        e.alpha = r.f32("entries");
    }
    return m;
}

std::uint64_t le64(const unsigned char* p) {
    std::uint64_t v = 0;
    for (int i = 0; i < 8; ++i) v |= std::uint64_t{p[i]} << (8 * i);
    return v;
}

}  // namespace

Result<std::vector<unsigned char>> model_bytes(const Model& model, const fs::path& path) {
    if (auto v = model.validate(); !v)
        return make_error(path.string() + ": not saved: " + v.error().message);
    return serialize(model);
}

Result<void> write_model(const Model& model, const fs::path& path) {
    const std::string where = path.string() + ": ";
    auto file = model_bytes(model, path);
    if (!file) return file.error();
    const std::vector<unsigned char>& bytes = *file;
    const fs::path tmp = path.string() + ".tmp";
    std::FILE* f = std::fopen(tmp.c_str(), "wb");
    if (!f) return make_error(tmp.string() + ": cannot open for writing: " + std::strerror(errno));
    bool ok = std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size();
    ok = std::fflush(f) == 0 && ok;
    ok = ::fsync(::fileno(f)) == 0 && ok;  // the rename must not publish unwritten data
    ok = std::fclose(f) == 0 && ok;
    std::error_code ec;
    if (!ok) {
        fs::remove(tmp, ec);
        return make_error(tmp.string() + ": write failed");
    }
    fs::rename(tmp, path, ec);
    if (ec) {
        fs::remove(tmp, ec);
        return make_error(where + "cannot rename " + tmp.string() + " to it: " + ec.message());
    }
    return {};
}

Result<Model> read_model(const fs::path& path) {
    auto file = io::read_bytes(path);
    if (!file) return file.error();
    return parse_model(file->data, path);
}

Result<Model> parse_model(std::span<const unsigned char> b, const fs::path& path) {
    const std::string where = path.string() + ": ";
    const std::size_t n_magic = std::min(b.size(), kMagic.size());
    if (b.empty()) return make_error(where + "empty file, not a hotgauge model file");
    if (std::memcmp(b.data(), kMagic.data(), n_magic) != 0)
        return make_error(where + "not a hotgauge model file (no HGPPF magic)");
    if (b.size() < kHeaderBytes)
        return make_error(where + "truncated: " + std::to_string(b.size()) +
                          " bytes, shorter than the header");
    Reader header(b.data(), b.size(), kMagic.size());
    const std::uint32_t version = header.u32("version");
    if (version != kModelFormatVersion)
        return make_error(where + "model format version " + std::to_string(version) +
                          ", this build reads " + std::to_string(kModelFormatVersion) +
                          ": rebuild with `hotgauge model build`");
    const std::uint64_t body = header.u64("body size");
    const std::uint64_t available = b.size() - kHeaderBytes;
    if (body > available || available - body < kChecksumBytes)
        return make_error(
            where + "truncated: " + std::to_string(b.size()) + " bytes, the header announces " +
            std::to_string(kHeaderBytes + body + kChecksumBytes) + " (or the header is corrupt)");
    if (available - body > kChecksumBytes)
        return make_error(where + "corrupt: " + std::to_string(available - body - kChecksumBytes) +
                          " unexpected bytes after the checksum");
    const std::size_t end = kHeaderBytes + static_cast<std::size_t>(body);
    if (io::fnv1a64(b.data(), end) != le64(b.data() + end))
        return make_error(where + "corrupt: checksum mismatch");
    // The checksum matched, so the body is what some writer wrote; still check every count.
    Reader r(b.data(), end, kHeaderBytes);
    Model m = deserialize(r);
    if (!r.ok()) return make_error(where + "corrupt: " + r.error);
    if (r.pos() != end)
        return make_error(where + "corrupt: " + std::to_string(end - r.pos()) +
                          " unread bytes in the body");
    if (auto v = m.validate(); !v) return make_error(where + "invalid model: " + v.error().message);
    return m;
}

}  // namespace hotgauge::model
