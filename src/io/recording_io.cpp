// Recording format v1 reader and writer (docs/recording-format.md; the contract is
// recording-format-v1.md). Every check here is mirrored in both directions: the writer refuses
// what the reader would reject.
#include "hotgauge/io/recording_io.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <set>
#include <sstream>
#include <system_error>

#include "hotgauge/core/geometry.hpp"
#include "hotgauge/io/npy.hpp"
#include "hotgauge/io/yaml_reader.hpp"
#include "hotgauge/io/yaml_writer.hpp"

namespace hotgauge::io {
namespace {

static_assert(std::endian::native == std::endian::little,
              "recording arrays are little-endian and copied as raw bytes");

namespace fs = std::filesystem;
using core::Error;
using core::FaceScan;
using core::make_error;
using core::Recording;
using core::Result;

constexpr double kRotationTol = 1e-6;            // recording-format-v1: rotations and unit vectors
constexpr double kLastRowTol = 1e-12;            // camera_to_world last row must be [0,0,0,1]
constexpr std::int64_t kMarginNs = 500'000'000;  // accelerometer coverage margin, 0.5 s

std::string where(const fs::path& path) { return path.string() + ": "; }

std::string line_of(const YAML::Node& node) {
    const YAML::Mark m = node.Mark();
    return m.is_null() ? std::string() : " (line " + std::to_string(m.line + 1) + ")";
}

// ---- YAML reading helpers. All return an error text without the file prefix. ----

// A YAML file of a recording is a few hundred bytes; one of megabytes is not one.
constexpr std::uint64_t kYamlMaxBytes = 1 << 20;

Result<YAML::Node> load_yaml(const FileSource& files, const fs::path& path) {
    auto file = files(path);
    if (!file) return file.error();
    if (file->size > kYamlMaxBytes)
        return make_error(where(path) + std::to_string(file->size) +
                          " bytes, too large for a recording's YAML file");
    std::string text(static_cast<std::size_t>(file->size), '\0');
    if (auto ok = file->read(0, text.size(), text.data()); !ok) return ok.error();
    try {
        YAML::Node doc = YAML::Load(std::string(text));
        if (!doc.IsMap())
            return make_error(where(path) + "top level is not a YAML mapping" + line_of(doc));
        return doc;
    } catch (const YAML::Exception& e) {
        if (e.mark.is_null()) return make_error(where(path) + "cannot read YAML: " + e.msg);
        const YamlSyntaxError at = yaml_syntax_error(text, e);
        return make_error(where(path) + "YAML syntax error at line " + std::to_string(at.line) +
                          (at.column > 0 ? ", column " + std::to_string(at.column) : "") + ": " +
                          at.message);
    }
}

// A YAML number: a plain (unquoted) scalar that parses as a double. Quoted scalars are strings.
std::optional<double> as_number(const YAML::Node& node) {
    if (!node.IsScalar() || node.Tag() == "!") return std::nullopt;
    double v = 0.0;
    if (!YAML::convert<double>::decode(node, v)) return std::nullopt;
    return v;
}

std::optional<std::string> required_string(const YAML::Node& doc, const char* key,
                                           std::string& out) {
    const YAML::Node n = doc[key];
    if (!n) return std::string("missing key '") + key + "'";
    if (!n.IsScalar()) return std::string("'") + key + "' must be a string" + line_of(n);
    out = n.Scalar();
    return std::nullopt;
}

// A rows x cols matrix of finite numbers (cols == 0: a flat vector of `rows` numbers).
std::optional<std::string> number_matrix(const YAML::Node& doc, const char* key, int rows, int cols,
                                         Eigen::MatrixXd& out) {
    const YAML::Node n = doc[key];
    const std::string what = std::string("'") + key + "'";
    const std::string expected =
        cols ? "a " + std::to_string(rows) + "x" + std::to_string(cols) + " list of rows"
             : "a list of " + std::to_string(rows) + " numbers";
    if (!n) return "missing key " + what;
    if (!n.IsSequence() || static_cast<int>(n.size()) != rows)
        return what + " must be " + expected + line_of(n);
    out.resize(rows, cols ? cols : 1);
    for (int r = 0; r < rows; ++r) {
        const YAML::Node row = n[r];
        for (int c = 0; c < (cols ? cols : 1); ++c) {
            if (cols && (!row.IsSequence() || static_cast<int>(row.size()) != cols))
                return what + " must be " + expected + "; row " + std::to_string(r) +
                       " is not a list of " + std::to_string(cols) + " numbers" + line_of(row);
            // Never assign YAML::Node objects: operator= writes through to the document.
            const YAML::Node item = cols ? row[c] : row;
            const auto v = as_number(item);
            if (!v)
                return what + " element [" + std::to_string(r) + (cols ? "][" : "") +
                       (cols ? std::to_string(c) : "") + "] is not a number" + line_of(item);
            if (!std::isfinite(*v))
                return what + " element [" + std::to_string(r) + (cols ? "][" : "") +
                       (cols ? std::to_string(c) : "") + "] is not finite" + line_of(item);
            out(r, c) = *v;
        }
    }
    return std::nullopt;
}

// ---- Invariants shared by reader and writer. ----

std::optional<std::string> check_face_name(const std::string& name) {
    if (name.empty() || name == "." || name == ".." ||
        name.find_first_of("/\\") != std::string::npos || name.find('\0') != std::string::npos)
        return "face name '" + name + "' is not a plain folder name";
    return std::nullopt;
}

std::string rotation_problem(const char* key, const Eigen::Matrix3d& R) {
    const double orth = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    std::ostringstream s;
    s << key << " is not a proper rotation (expected RᵀR = I and det R = +1 within " << kRotationTol
      << "; found max |RᵀR - I| = " << orth << ", det R = " << R.determinant() << ")";
    return s.str();
}

std::optional<std::string> check_pose(const Eigen::Matrix4d& T, const Eigen::Vector3d& scan,
                                      const Eigen::Matrix3d& R_acc) {
    if (!T.allFinite()) return "camera_to_world has non-finite values";
    const Eigen::RowVector4d last = T.row(3);
    if ((last - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > kLastRowTol) {
        std::ostringstream s;
        s << "camera_to_world last row must be [0, 0, 0, 1], found [" << last(0) << ", " << last(1)
          << ", " << last(2) << ", " << last(3) << "]";
        return s.str();
    }
    if (!core::is_rotation(T.topLeftCorner<3, 3>(), kRotationTol))
        return rotation_problem("camera_to_world rotation part", T.topLeftCorner<3, 3>());
    if (!scan.allFinite() || std::abs(scan.norm() - 1.0) > kRotationTol) {
        std::ostringstream s;
        s.precision(17);
        s << "scan_direction is not a unit vector (expected norm 1 within " << kRotationTol
          << ", found " << scan.norm() << ")";
        return s.str();
    }
    if (!core::is_rotation(R_acc, kRotationTol)) return rotation_problem("accel_to_camera", R_acc);
    return std::nullopt;
}

// First index i with t[i] <= t[i-1], or -1.
std::int64_t first_non_increasing(const std::vector<std::int64_t>& t) {
    for (std::size_t i = 1; i < t.size(); ++i)
        if (t[i] <= t[i - 1]) return static_cast<std::int64_t>(i);
    return -1;
}

std::string increasing_problem(const std::vector<std::int64_t>& t, std::int64_t i) {
    return "timestamps not strictly increasing: index " + std::to_string(i) + " has " +
           std::to_string(t[i]) + " ns after " + std::to_string(t[i - 1]) + " ns at index " +
           std::to_string(i - 1);
}

// Checks the array invariants of a face; errors name the file they concern under `dir`.
Result<void> check_arrays(const FaceScan& f, const fs::path& dir) {
    const auto N = static_cast<std::size_t>(f.n_profiles());
    const auto K = static_cast<std::size_t>(f.n_accel());
    if (f.width < 0)
        return make_error(where(dir / "profiles.npy") + "negative width " +
                          std::to_string(f.width));
    const std::size_t want_prof = N * static_cast<std::size_t>(f.width) * 2;
    if (f.profiles_mm.size() != want_prof)
        return make_error(where(dir / "profiles.npy") + std::to_string(f.profiles_mm.size()) +
                          " values, expected N*W*2 = " + std::to_string(want_prof) + " for N = " +
                          std::to_string(N) + " profiles of W = " + std::to_string(f.width));
    if (f.profile_positions_mm.size() != N)
        return make_error(where(dir / "profile_positions.npy") +
                          std::to_string(f.profile_positions_mm.size()) + " entries, expected " +
                          std::to_string(N) + " (one per profile)");
    if (f.accel_mps2.size() != K * 3)
        return make_error(where(dir / "accel.npy") + std::to_string(f.accel_mps2.size()) +
                          " values, expected K*3 = " + std::to_string(K * 3) +
                          " for K = " + std::to_string(K) + " samples in accel_times.npy");
    if (const auto i = first_non_increasing(f.profile_times_ns); i >= 0)
        return make_error(where(dir / "profile_times.npy") +
                          increasing_problem(f.profile_times_ns, i));
    if (const auto i = first_non_increasing(f.accel_times_ns); i >= 0)
        return make_error(where(dir / "accel_times.npy") + increasing_problem(f.accel_times_ns, i));
    for (std::size_t k = 0; k < N; ++k)
        if (!std::isfinite(f.profile_positions_mm[k]))
            return make_error(where(dir / "profile_positions.npy") + "non-finite value " +
                              std::to_string(f.profile_positions_mm[k]) + " at index " +
                              std::to_string(k) + ", expected finite encoder positions");
    return {};
}

// a - b saturated to the int64 range (timestamps may be anywhere on the clock).
std::int64_t sat_sub(std::int64_t a, std::int64_t b) {
    std::int64_t r = 0;
    if (__builtin_sub_overflow(a, b, &r))
        return a > b ? std::numeric_limits<std::int64_t>::max()
                     : std::numeric_limits<std::int64_t>::min();
    return r;
}

void add_face_warnings(const FaceScan& f, const fs::path& dir, std::vector<std::string>& out) {
    const std::int64_t K = f.n_accel();
    std::int64_t bad = 0, first_bad = -1;
    for (std::int64_t j = 0; j < K; ++j) {
        if (!f.accel(j).allFinite()) {
            if (first_bad < 0) first_bad = j;
            ++bad;
        }
    }
    if (bad)
        out.push_back(where(dir / "accel.npy") + std::to_string(bad) + " of " + std::to_string(K) +
                      " samples have non-finite values (first at index " +
                      std::to_string(first_bad) + ")");
    if (f.n_profiles() == 0) return;
    const std::int64_t t0 = f.profile_times_ns.front(), t1 = f.profile_times_ns.back();
    if (K == 0) {
        out.push_back(where(dir) + "no accelerometer samples for " +
                      std::to_string(f.n_profiles()) + " profiles");
        return;
    }
    const std::int64_t before = sat_sub(t0, f.accel_times_ns.front());
    const std::int64_t after = sat_sub(f.accel_times_ns.back(), t1);
    if (before < kMarginNs || after < kMarginNs) {
        std::ostringstream s;
        s << where(dir) << "accelerometer does not cover the scan with 0.5 s margins (found "
          << static_cast<double>(before) * 1e-9 << " s before the first profile, "
          << static_cast<double>(after) * 1e-9 << " s after the last)";
        out.push_back(s.str());
    }
}

// ---- Arrays. ----

std::string shape_str(const std::vector<std::int64_t>& shape) {
    std::string s = "(";
    for (std::size_t i = 0; i < shape.size(); ++i) s += (i ? ", " : "") + std::to_string(shape[i]);
    return s + (shape.size() == 1 ? ",)" : ")");
}

// An array file and its header.
struct Array {
    FileParts file;
    NpyArray header;
};

// Reads `name` under `dir` and checks dtype, C order and shape: `dims` dimensions, the trailing
// ones equal to `tail` (-1: any).
Result<Array> read_array(const FileSource& files, const fs::path& dir, const char* name,
                         const char* descr, std::size_t dims, std::vector<std::int64_t> tail,
                         const char* expected_shape) {
    const fs::path path = dir / name;
    auto file = files(path);
    if (!file) return file.error();
    std::vector<unsigned char> head(std::min<std::uint64_t>(file->size, kNpyHeaderMax));
    if (auto ok = file->read(0, head.size(), head.data()); !ok) return ok.error();
    auto arr = parse_npy_header(head, path, file->size);  // the data is read after every check
    if (!arr) return arr.error();
    if (arr->descr != descr)
        return make_error(where(path) + "dtype '" + arr->descr + "', expected '" + descr + "'");
    if (arr->fortran_order)
        return make_error(where(path) +
                          "fortran_order is True, recording format v1 requires C order");
    bool ok = arr->shape.size() == dims;
    for (std::size_t i = 0; ok && i < tail.size(); ++i)
        if (tail[i] >= 0 && arr->shape[dims - tail.size() + i] != tail[i]) ok = false;
    if (!ok)
        return make_error(where(path) + "shape " + shape_str(arr->shape) + ", expected " +
                          expected_shape);
    return Array{std::move(*file), std::move(*arr)};
}

// Every value that is not finite (±Inf, a NaN of any payload) made the quiet NaN, written only
// where it changes: most samples without a return are that NaN already, and a store to each would
// dirty four fifths of a side face's memory. Tested in blocks of a fixed size, a loop the compiler
// vectorizes: about one instruction per four values.
constexpr std::uint32_t kExponentBits = 0x7f800000u;
constexpr float kQuietNaN = std::numeric_limits<float>::quiet_NaN();
constexpr std::uint32_t kQuietNaNBits = std::bit_cast<std::uint32_t>(kQuietNaN);
constexpr int kNaNBlock = 16;

bool to_change(float v) {
    const auto b = std::bit_cast<std::uint32_t>(v);
    return (b & kExponentBits) == kExponentBits && b != kQuietNaNBits;
}

// Not inlined: GCC 12 vectorizes this loop on its own, not inside the caller's.
[[gnu::noinline]] bool block_to_change(const float* v) {
    std::uint32_t b[kNaNBlock];
    std::memcpy(b, v, sizeof b);
    std::uint32_t any = 0;
    for (int j = 0; j < kNaNBlock; ++j)
        any |= static_cast<std::uint32_t>((b[j] & kExponentBits) == kExponentBits) &
               static_cast<std::uint32_t>(b[j] != kQuietNaNBits);
    return any != 0;
}

void to_quiet_nan(float* values, std::size_t n) {
    std::size_t at = 0;
    for (; at + kNaNBlock <= n; at += kNaNBlock) {
        if (!block_to_change(values + at)) continue;
        for (std::size_t j = at; j < at + kNaNBlock; ++j)
            if (to_change(values[j])) values[j] = kQuietNaN;
    }
    for (; at < n; ++at)
        if (to_change(values[at])) values[at] = kQuietNaN;
}

// The data of `a` into `out` through a buffer of kChunkBytes: `out` is not zero-filled first (as
// resize() would, a pass over all of it) and `fix(data, n)` works on each chunk while it is in
// the cache. The chunk is reused; `out` grows into its reserved size without a reallocation.
constexpr std::size_t kChunkBytes = 256 << 10;
template <class T, class Fix>
Result<void> read_into(const Array& a, std::vector<T>& out, Fix&& fix) {
    const std::size_t n = a.header.data_bytes / sizeof(T), per_chunk = kChunkBytes / sizeof(T);
    std::vector<T> chunk(std::min(n, per_chunk));
    out.clear();
    out.reserve(n);
    for (std::size_t at = 0; at < n; at += per_chunk) {
        const std::size_t m = std::min(per_chunk, n - at);
        if (auto ok =
                a.file.read(a.header.data_offset + at * sizeof(T), m * sizeof(T), chunk.data());
            !ok)
            return ok;
        fix(chunk.data(), m);
        out.insert(out.end(), chunk.begin(), chunk.begin() + static_cast<std::ptrdiff_t>(m));
    }
    return {};
}
template <class T>
Result<void> read_into(const Array& a, std::vector<T>& out) {
    return read_into(a, out, [](T*, std::size_t) {});
}

Result<FaceScan> read_face(const FileSource& files, const fs::path& root, const std::string& name) {
    FaceScan f;
    f.name = name;
    const fs::path dir = root / name;
    const fs::path fy = dir / "face.yaml";
    auto doc = load_yaml(files, fy);
    if (!doc) return doc.error();
    Eigen::MatrixXd T, s, R;
    if (auto e = number_matrix(*doc, "camera_to_world", 4, 4, T)) return make_error(where(fy) + *e);
    if (auto e = number_matrix(*doc, "scan_direction", 3, 0, s)) return make_error(where(fy) + *e);
    if (auto e = number_matrix(*doc, "accel_to_camera", 3, 3, R)) return make_error(where(fy) + *e);
    if (auto e = check_pose(T, s, R)) return make_error(where(fy) + *e);
    f.T_world_camera.linear() = T.topLeftCorner<3, 3>();
    f.T_world_camera.translation() = T.topRightCorner<3, 1>();
    f.T_world_camera.makeAffine();
    f.scan_direction = s.col(0);
    f.R_camera_accel = R;
    if (const YAML::Node n = (*doc)["travel_scale"]) {
        const auto v = as_number(n);
        if (!v || !(*v > 0.0) || !std::isfinite(*v))
            return make_error(where(fy) + "'travel_scale' must be a positive number" + line_of(n));
        f.travel_scale = *v;
    }
    if (const YAML::Node n = (*doc)["clock_offset_ns"]) {
        const auto v = as_number(n);
        if (!v || !std::isfinite(*v) || *v != std::round(*v) || std::abs(*v) > 1e15)
            return make_error(where(fy) + "'clock_offset_ns' must be an integer" + line_of(n));
        f.clock_offset_ns = static_cast<std::int64_t>(*v);
    }
    if (const YAML::Node n = (*doc)["geometry_source"]) {
        if (!n.IsScalar() || n.Scalar() != "calibration")
            return make_error(where(fy) + "'geometry_source' must be 'calibration'" + line_of(n));
        f.geometry_from_calibration = true;
    }

    auto prof = read_array(files, dir, "profiles.npy", "<f4", 3, {-1, 2}, "(N, W, 2)");
    if (!prof) return prof.error();
    auto pt = read_array(files, dir, "profile_times.npy", "<i8", 1, {}, "(N,)");
    if (!pt) return pt.error();
    auto pp = read_array(files, dir, "profile_positions.npy", "<f8", 1, {}, "(N,)");
    if (!pp) return pp.error();
    auto acc = read_array(files, dir, "accel.npy", "<f4", 2, {3}, "(K, 3)");
    if (!acc) return acc.error();
    auto at = read_array(files, dir, "accel_times.npy", "<i8", 1, {}, "(K,)");
    if (!at) return at.error();

    const std::int64_t N = prof->header.shape[0];
    if (pt->header.shape[0] != N)
        return make_error(where(dir / "profile_times.npy") + std::to_string(pt->header.shape[0]) +
                          " entries, expected " + std::to_string(N) +
                          " (one per profile in profiles.npy)");
    if (pp->header.shape[0] != N)
        return make_error(where(dir / "profile_positions.npy") +
                          std::to_string(pp->header.shape[0]) + " entries, expected " +
                          std::to_string(N) + " (one per profile in profiles.npy)");
    if (acc->header.shape[0] != at->header.shape[0])
        return make_error(where(dir / "accel_times.npy") + std::to_string(at->header.shape[0]) +
                          " entries, expected " + std::to_string(acc->header.shape[0]) +
                          " (one per sample in accel.npy)");
    f.width = prof->header.shape[1];
    // One after the other: the first file that cannot be read ends it.
    // A point is a pair of finite numbers; ±Inf is no more a point than NaN is.
    if (auto ok = read_into(*prof, f.profiles_mm, to_quiet_nan); !ok) return ok.error();
    if (auto ok = read_into(*pt, f.profile_times_ns); !ok) return ok.error();
    if (auto ok = read_into(*pp, f.profile_positions_mm); !ok) return ok.error();
    if (auto ok = read_into(*acc, f.accel_mps2); !ok) return ok.error();
    if (auto ok = read_into(*at, f.accel_times_ns); !ok) return ok.error();
    if (auto ok = check_arrays(f, dir); !ok) return ok.error();
    return f;
}

Result<Recording> read_recording_impl(const fs::path& dir, const FileSource& files) {
    const fs::path py = dir / "part.yaml";
    auto doc = load_yaml(files, py);
    if (!doc) return doc.error();
    const YAML::Node& d = *doc;
    Recording rec;

    const YAML::Node fmt = d["format"];
    if (!fmt) return make_error(where(py) + "missing key 'format'");
    if (!fmt.IsScalar() || fmt.Scalar() != kRecordingFormat)
        return make_error(where(py) + "unknown format version '" +
                          (fmt.IsScalar() ? fmt.Scalar() : std::string("<not a string>")) +
                          "', expected '" + kRecordingFormat + "'");
    if (auto e = required_string(d, "part_id", rec.part_id)) return make_error(where(py) + *e);
    if (auto e = required_string(d, "recipe", rec.recipe)) return make_error(where(py) + *e);
    if (auto e = required_string(d, "captured_at", rec.captured_at))
        return make_error(where(py) + *e);
    if (const YAML::Node t = d["temperature_c"]) {
        const auto v = as_number(t);
        if (!v || !std::isfinite(*v))
            return make_error(where(py) + "'temperature_c' must be a finite number, found '" +
                              (t.IsScalar() ? t.Scalar() : std::string("<not a scalar>")) + "'" +
                              line_of(t));
        rec.temperature_c = *v;
    }
    const YAML::Node faces = d["faces"];
    if (!faces) return make_error(where(py) + "missing key 'faces'");
    if (!faces.IsSequence() || faces.size() == 0)
        return make_error(where(py) + "'faces' must be a non-empty list of folder names" +
                          line_of(faces));
    std::set<std::string> seen;
    for (const YAML::Node& n : faces) {
        if (!n.IsScalar())
            return make_error(where(py) + "'faces' entries must be folder names" + line_of(n));
        const std::string name = n.Scalar();
        if (auto e = check_face_name(name)) return make_error(where(py) + *e + line_of(n));
        if (!seen.insert(name).second)
            return make_error(where(py) + "face '" + name + "' is listed twice" + line_of(n));
        auto face = read_face(files, dir, name);
        if (!face) return face.error();
        add_face_warnings(*face, dir / name, rec.warnings);
        rec.faces.push_back(std::move(*face));
    }
    return rec;
}

// ---- Writing. ----

Result<void> validate(const Recording& rec, const fs::path& dir) {
    const fs::path py = dir / "part.yaml";
    if (rec.faces.empty()) return make_error(where(py) + "a recording needs at least one face");
    if (rec.temperature_c && !std::isfinite(*rec.temperature_c))
        return make_error(where(py) + "temperature_c must be finite or absent");
    std::set<std::string> seen;
    for (const FaceScan& f : rec.faces) {
        if (auto e = check_face_name(f.name)) return make_error(where(py) + *e);
        if (!seen.insert(f.name).second)
            return make_error(where(py) + "face '" + f.name + "' is listed twice");
        const fs::path fdir = dir / f.name;
        if (auto e = check_pose(f.T_world_camera.matrix(), f.scan_direction, f.R_camera_accel))
            return make_error(where(fdir / "face.yaml") + *e);
        if (auto ok = check_arrays(f, fdir); !ok) return ok;
    }
    return {};
}

// face.yaml and the arrays of `f`, as files under `dir`, each to `out` as soon as it is made.
Result<void> face_files(const FaceScan& f, const fs::path& dir, const RecordingFile& out) {
    const Eigen::Matrix4d T = f.T_world_camera.matrix();
    std::string y = "camera_to_world: [";
    for (int r = 0; r < 4; ++r) {
        const Eigen::RowVector4d row = T.row(r);
        y += (r ? ", " : "") + fmt_row(row.data(), 4);
    }
    y += "]\nscan_direction: " + fmt_row(f.scan_direction.data(), 3) + "\naccel_to_camera: [";
    for (int r = 0; r < 3; ++r) {
        const Eigen::RowVector3d row = f.R_camera_accel.row(r);
        y += (r ? ", " : "") + fmt_row(row.data(), 3);
    }
    y += "]\n";
    // Our own keys (readers of the contract ignore them): what the capture already applied.
    if (f.travel_scale != 1.0) y += "travel_scale: " + fmt_double(f.travel_scale) + "\n";
    if (f.clock_offset_ns != 0) y += "clock_offset_ns: " + std::to_string(f.clock_offset_ns) + "\n";
    if (f.geometry_from_calibration) y += "geometry_source: calibration\n";
    if (auto ok = out(dir / "face.yaml", std::move(y)); !ok) return ok;

    const std::int64_t N = f.n_profiles(), K = f.n_accel();
    const auto array = [&](const char* name, const char* descr, std::vector<std::int64_t> shape,
                           const auto& v) -> Result<void> {
        auto bytes = npy_bytes(dir / name, descr, shape, v.data(), v.size() * sizeof(v[0]));
        if (!bytes) return bytes.error();
        return out(dir / name, std::move(*bytes));
    };
    if (auto ok = array("profiles.npy", "<f4", {N, f.width, 2}, f.profiles_mm); !ok) return ok;
    if (auto ok = array("profile_times.npy", "<i8", {N}, f.profile_times_ns); !ok) return ok;
    if (auto ok = array("profile_positions.npy", "<f8", {N}, f.profile_positions_mm); !ok)
        return ok;
    if (auto ok = array("accel.npy", "<f4", {K, 3}, f.accel_mps2); !ok) return ok;
    return array("accel_times.npy", "<i8", {K}, f.accel_times_ns);
}

}  // namespace

core::Result<core::Recording> read_recording(const std::filesystem::path& dir,
                                             const FileSource& files) {
    try {
        return read_recording_impl(dir, files);
    } catch (const std::exception& e) {  // e.g. bad_alloc: never escapes
        return make_error(where(dir) + "cannot read recording: " + e.what());
    }
}

core::Result<core::Recording> read_recording(const std::filesystem::path& dir) {
    return read_recording(dir, open_parts);
}

core::Result<void> recording_files(const core::Recording& rec, const std::filesystem::path& dir,
                                   const RecordingFile& file) {
    try {
        if (auto ok = validate(rec, dir); !ok) return ok;
        for (const FaceScan& f : rec.faces)
            if (auto ok = face_files(f, dir / f.name, file); !ok) return ok;
        std::string y = "format: " + std::string(kRecordingFormat) + "\n";
        y += "part_id: " + quote(rec.part_id) + "\n";
        y += "recipe: " + quote(rec.recipe) + "\n";
        y += "captured_at: " + quote(rec.captured_at) + "\n";
        if (rec.temperature_c) y += "temperature_c: " + fmt_double(*rec.temperature_c) + "\n";
        y += "faces: [";
        for (std::size_t i = 0; i < rec.faces.size(); ++i)
            y += (i ? ", " : "") + quote(rec.faces[i].name);
        y += "]\n";
        return file(dir / "part.yaml", std::move(y));
    } catch (const std::exception& e) {
        return make_error(where(dir) + "cannot write recording: " + e.what());
    }
}

core::Result<void> write_recording(const core::Recording& rec, const std::filesystem::path& dir) {
    if (auto ok = validate(rec, dir); !ok) return ok;  // before anything is removed
    std::error_code ec;
    fs::remove(dir / "part.yaml", ec);  // see below
    // part.yaml last: a recording interrupted while writing has no part.yaml and is not mistaken
    // for a complete one. Each file is written as soon as it is made: one file in memory at once.
    return recording_files(rec, dir, [&](const fs::path& path, std::string&& bytes) {
        fs::create_directories(path.parent_path(), ec);
        if (ec)
            return Result<void>(
                make_error(where(path.parent_path()) + "cannot create directory: " + ec.message()));
        return write_text(path, bytes);
    });
}

}  // namespace hotgauge::io
