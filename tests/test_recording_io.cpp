// Recording format v1: bit-exact round trips, interoperability with NumPy and the independent
// validator (/work/shared/tools/validate-recording), and one test per contract violation.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "hotgauge/io/npy.hpp"
#include "hotgauge/io/ply.hpp"
#include "hotgauge/io/recording_io.hpp"
#include "temp_dir.hpp"

namespace fs = std::filesystem;
using hotgauge::core::FaceScan;
using hotgauge::core::Recording;
using hotgauge::io::read_recording;
using hotgauge::io::write_npy;
using hotgauge::io::write_recording;

namespace {

// The system Python with Debian's python3-numpy (tests/CMakeLists.txt may override it).
#ifdef HOTGAUGE_PYTHON
const std::string kPython = HOTGAUGE_PYTHON;
#else
const std::string kPython = "/usr/bin/python3";
#endif

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

using hotgauge::test::TempDir;

std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void dump(const fs::path& p, const std::string& bytes) {
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out << bytes;
}

int run(const std::string& cmd, std::string& out) {
    out.clear();
    FILE* p = ::popen(cmd.c_str(), "r");
    if (!p) return -1;
    char buf[4096];
    std::size_t n = 0;
    while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
    const int status = ::pclose(p);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

bool have_numpy() {
    std::string out;
    return fs::exists(kPython) && run(kPython + " -c 'import numpy' 2>/dev/null", out) == 0;
}

// A face with random data: N profiles of W points (some NaN), K accelerometer samples covering the
// profiles with 0.6 s margins (K = 0: no accelerometer record).
FaceScan make_face(std::mt19937& rng, const std::string& name, std::int64_t N, std::int64_t W,
                   bool with_accel) {
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    FaceScan f;
    f.name = name;
    const Eigen::Quaterniond q = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized();
    f.T_world_camera.linear() = q.toRotationMatrix();
    f.T_world_camera.translation() = Eigen::Vector3d(u(rng), u(rng), u(rng)) * 400.0;
    f.scan_direction = Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized();
    f.R_camera_accel =
        Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized().toRotationMatrix();
    f.width = W;
    for (std::int64_t i = 0; i < N * W * 2; ++i)
        f.profiles_mm.push_back(i % 7 == 3 ? kNaN : static_cast<float>(u(rng) * 80.0));
    std::int64_t t = 1'700'000'000'000'000'000 + static_cast<std::int64_t>(u(rng) * 1e6);
    for (std::int64_t k = 0; k < N; ++k) {
        f.profile_times_ns.push_back(t);
        t += 1'000'000 + static_cast<std::int64_t>(u(rng) * 1000);
        f.profile_positions_mm.push_back(static_cast<double>(k) * 0.2 + u(rng) * 1e-3);
    }
    if (with_accel) {
        for (std::int64_t ta = f.profile_times_ns.front() - 600'000'000;
             ta <= f.profile_times_ns.back() + 600'000'000; ta += 9'999'937) {
            f.accel_times_ns.push_back(ta);
            for (int c = 0; c < 3; ++c)
                f.accel_mps2.push_back(static_cast<float>(u(rng) + (c == 2 ? 9.81 : 0.0)));
        }
    }
    return f;
}

Recording make_recording(unsigned seed = 7) {
    std::mt19937 rng(seed);
    Recording rec;
    rec.part_id = "H-000123";
    rec.recipe = "hub-a";
    rec.captured_at = "2026-11-21T10:15:00Z";
    rec.temperature_c = 1050.123456789;
    rec.faces.push_back(make_face(rng, "top", 6, 5, true));
    rec.faces.push_back(make_face(rng, "side1", 3, 4, false));  // K = 0
    return rec;
}

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
    return a.size() == b.size() &&
           (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

template <class M>
bool same_bits_m(const M& a, const M& b) {
    return std::memcmp(a.data(), b.data(), sizeof(typename M::Scalar) * a.size()) == 0;
}

void expect_same(const Recording& a, const Recording& b) {
    EXPECT_EQ(a.part_id, b.part_id);
    EXPECT_EQ(a.recipe, b.recipe);
    EXPECT_EQ(a.captured_at, b.captured_at);
    ASSERT_EQ(a.temperature_c.has_value(), b.temperature_c.has_value());
    if (a.temperature_c) {
        EXPECT_EQ(*a.temperature_c, *b.temperature_c);
    }
    ASSERT_EQ(a.faces.size(), b.faces.size());
    for (std::size_t i = 0; i < a.faces.size(); ++i) {
        const FaceScan &x = a.faces[i], &y = b.faces[i];
        SCOPED_TRACE(x.name);
        EXPECT_EQ(x.name, y.name);
        EXPECT_TRUE(same_bits_m(x.T_world_camera.matrix(), y.T_world_camera.matrix()));
        EXPECT_TRUE(same_bits_m(x.scan_direction, y.scan_direction));
        EXPECT_TRUE(same_bits_m(x.R_camera_accel, y.R_camera_accel));
        EXPECT_EQ(x.width, y.width);
        EXPECT_TRUE(same_bits(x.profiles_mm, y.profiles_mm));
        EXPECT_TRUE(same_bits(x.profile_times_ns, y.profile_times_ns));
        EXPECT_TRUE(same_bits(x.profile_positions_mm, y.profile_positions_mm));
        EXPECT_TRUE(same_bits(x.accel_mps2, y.accel_mps2));
        EXPECT_TRUE(same_bits(x.accel_times_ns, y.accel_times_ns));
    }
}

std::string hex(const void* p, std::size_t n) {
    static const char* digits = "0123456789abcdef";
    std::string s;
    for (std::size_t i = 0; i < n; ++i) {
        const auto b = static_cast<const unsigned char*>(p)[i];
        s += digits[b >> 4];
        s += digits[b & 15];
    }
    return s;
}

bool contains(const std::string& s, const std::string& part) {
    return s.find(part) != std::string::npos;
}

}  // namespace

TEST(RecordingIo, RoundTripIsBitExact) {
    TempDir tmp;
    Recording rec = make_recording();
    rec.part_id = "H-\"0001\"\\ x: y #z\té";  // quoting and escaping
    rec.faces[0].profile_positions_mm[0] = -0.0;
    rec.faces[0].T_world_camera.translation().x() = 1e-300;
    ASSERT_TRUE(write_recording(rec, tmp.path / "part").ok());
    auto back = read_recording(tmp.path / "part");
    ASSERT_TRUE(back.ok()) << back.error().message;
    expect_same(rec, *back);
    // The empty accelerometer record of side1 is allowed but warned about.
    ASSERT_EQ(back->warnings.size(), 1u);
    EXPECT_TRUE(contains(back->warnings[0], "side1")) << back->warnings[0];
    EXPECT_TRUE(contains(back->warnings[0], "no accelerometer samples")) << back->warnings[0];
}

// The reader on files in memory (the fuzz harness's entry point) reads what write_recording's
// files say, as the one on disk does; a file the source lacks is an error naming it.
TEST(RecordingIo, FilesInMemoryReadAsOnDisk) {
    TempDir tmp;
    const Recording rec = make_recording();
    ASSERT_TRUE(write_recording(rec, tmp.path / "part").ok());
    auto on_disk = read_recording(tmp.path / "part");
    ASSERT_TRUE(on_disk.ok()) << on_disk.error().message;
    std::vector<std::pair<fs::path, std::string>> files;
    auto made = hotgauge::io::recording_files(rec, "mem", [&](const fs::path& p, std::string&& b) {
        files.emplace_back(p, std::move(b));
        return hotgauge::core::Result<void>{};
    });
    ASSERT_TRUE(made.ok()) << made.error().message;
    EXPECT_EQ(files.back().first, fs::path("mem/part.yaml"));  // the last one written
    for (const auto& [path, bytes] : files)
        EXPECT_EQ(slurp(tmp.path / "part" / path.lexically_relative("mem")), bytes) << path;
    std::string left_out;
    const hotgauge::io::FileSource source =
        [&](const fs::path& path) -> hotgauge::core::Result<hotgauge::io::FileParts> {
        for (const auto& [p, bytes] : files)
            if (p == path && p.string() != left_out)
                return hotgauge::io::FileParts::of(hotgauge::io::Bytes::view(bytes));
        return hotgauge::core::make_error(path.string() + ": missing");
    };
    auto in_memory = read_recording("mem", source);
    ASSERT_TRUE(in_memory.ok()) << in_memory.error().message;
    expect_same(*on_disk, *in_memory);
    EXPECT_EQ(on_disk->warnings.size(), in_memory->warnings.size());
    left_out = "mem/top/accel_times.npy";
    in_memory = read_recording("mem", source);
    ASSERT_FALSE(in_memory.ok());
    EXPECT_EQ(in_memory.error().message, "mem/top/accel_times.npy: missing");
}

// Issue 18, finding 7: ±Inf in profiles.npy was counted as a point. A point is two finite
// numbers: an infinite value reads as NaN, the format's "no point".
TEST(RecordingIo, InfiniteProfileValuesAreNoPoints) {
    TempDir tmp;
    Recording rec = make_recording();
    auto& p = rec.faces[0].profiles_mm;
    std::vector<std::size_t> finite;
    for (std::size_t i = 0; i < p.size() && finite.size() < 3; ++i)
        if (std::isfinite(p[i])) finite.push_back(i);
    ASSERT_EQ(finite.size(), 3u);
    p[finite[0]] = std::numeric_limits<float>::infinity();
    p[finite[1]] = -std::numeric_limits<float>::infinity();
    // A NaN with a payload, in the first block of 16 values and in the last, shorter one (the
    // reader tests whole blocks at once): each reads as the one quiet NaN.
    const float payload_nan = std::bit_cast<float>(std::uint32_t{0x7fa00001u});
    p[1] = payload_nan;
    p[p.size() - 1] = payload_nan;
    ASSERT_NE(p.size() % 16, 0u) << "the test wants a last block shorter than 16";
    ASSERT_TRUE(write_recording(rec, tmp.path / "part").ok());
    auto back = read_recording(tmp.path / "part");
    ASSERT_TRUE(back.ok()) << back.error().message;
    const auto& q = back->faces[0].profiles_mm;
    EXPECT_TRUE(std::isnan(q[finite[0]]) && std::isnan(q[finite[1]]));
    EXPECT_EQ(q[finite[2]], p[finite[2]]);
    const auto quiet = std::bit_cast<std::uint32_t>(std::numeric_limits<float>::quiet_NaN());
    EXPECT_EQ(std::bit_cast<std::uint32_t>(q[1]), quiet);
    EXPECT_EQ(std::bit_cast<std::uint32_t>(q[q.size() - 1]), quiet);
    EXPECT_EQ(std::bit_cast<std::uint32_t>(q[finite[0]]), quiet);
}

TEST(RecordingIo, RoundTripWithoutTemperatureAndOverwrite) {
    TempDir tmp;
    Recording rec = make_recording(11);
    ASSERT_TRUE(write_recording(make_recording(3), tmp.path / "p").ok());
    rec.temperature_c.reset();
    ASSERT_TRUE(write_recording(rec, tmp.path / "p").ok());  // overwrites
    EXPECT_FALSE(contains(slurp(tmp.path / "p" / "part.yaml"), "temperature_c"));
    auto back = read_recording(tmp.path / "p");
    ASSERT_TRUE(back.ok()) << back.error().message;
    expect_same(rec, *back);
}

TEST(RecordingIo, WarnsOnNonFiniteAccelAndShortCoverage) {
    TempDir tmp;
    Recording rec = make_recording();
    FaceScan& f = rec.faces[0];
    f.accel_mps2[3 * 3 + 1] = kNaN;
    f.accel_mps2[7 * 3] = std::numeric_limits<float>::infinity();
    // Drop the last 30 samples: less than 0.5 s after the last profile.
    f.accel_times_ns.resize(f.accel_times_ns.size() - 30);
    f.accel_mps2.resize(f.accel_times_ns.size() * 3);
    ASSERT_TRUE(write_recording(rec, tmp.path).ok());
    auto back = read_recording(tmp.path);
    ASSERT_TRUE(back.ok()) << back.error().message;
    std::string all;
    for (const auto& w : back->warnings) all += w + "\n";
    EXPECT_TRUE(contains(all, (tmp.path / "top" / "accel.npy").string() + ": 2 of ")) << all;
    EXPECT_TRUE(contains(all, "first at index 3")) << all;
    EXPECT_TRUE(contains(all, (tmp.path / "top").string() +
                                  ": accelerometer does not cover the scan with 0.5 s margins"))
        << all;
    expect_same(rec, *back);  // NaNs come through untouched
}

TEST(RecordingIo, NumpyLoadsWhatWeWrite) {
    if (!have_numpy()) GTEST_SKIP() << kPython << " with numpy not available";
    TempDir tmp;
    const Recording rec = make_recording();
    ASSERT_TRUE(write_recording(rec, tmp.path / "part").ok());
    dump(tmp.path / "dump.py", R"PY(
import sys, numpy as np
d = sys.argv[1]
for face in sys.argv[2:]:
    for name in ["profiles", "profile_times", "profile_positions", "accel", "accel_times"]:
        a = np.load(d + "/" + face + "/" + name + ".npy", allow_pickle=False)
        assert a.flags.c_contiguous
        print(face, name, a.dtype.str, "x".join(str(n) for n in a.shape), a.tobytes().hex())
)PY");
    std::string out;
    ASSERT_EQ(run(kPython + " " + (tmp.path / "dump.py").string() + " " +
                      (tmp.path / "part").string() + " top side1",
                  out),
              0)
        << out;
    std::string expected;
    auto line = [&](const FaceScan& f, const char* name, const char* dtype,
                    const std::string& shape, const auto& v) {
        expected += f.name + " " + name + " " + dtype + " " + shape + " " +
                    hex(v.data(), v.size() * sizeof(v[0])) + "\n";
    };
    for (const FaceScan& f : rec.faces) {
        const std::string N = std::to_string(f.n_profiles()), K = std::to_string(f.n_accel());
        line(f, "profiles", "<f4", N + "x" + std::to_string(f.width) + "x2", f.profiles_mm);
        line(f, "profile_times", "<i8", N, f.profile_times_ns);
        line(f, "profile_positions", "<f8", N, f.profile_positions_mm);
        line(f, "accel", "<f4", K + "x3", f.accel_mps2);
        line(f, "accel_times", "<i8", K, f.accel_times_ns);
    }
    EXPECT_EQ(out, expected);
}

TEST(RecordingIo, ReadsWhatNumpyWrites) {
    if (!have_numpy()) GTEST_SKIP() << kPython << " with numpy not available";
    TempDir tmp;
    dump(tmp.path / "gen.py", R"PY(
import os, sys, numpy as np
d = sys.argv[1]
os.makedirs(d + "/top")
with open(d + "/part.yaml", "w") as f:
    f.write("# written by numpy\nformat: hotgauge-recording/1\npart_id: 'P-7'\nrecipe: hub-a\n"
            "captured_at: 2026-11-21T10:15:00Z\nfaces:\n  - top\noperator: someone\n")
with open(d + "/top/face.yaml", "w") as f:
    f.write("scan_direction: [0, 1, 0]\n"
            "camera_to_world: [[1,0,0,0],[0,-1,0,0],[0,0,-1,500],[0,0,0,1]]\n"
            "accel_to_camera:\n  - [1, 0, 0]\n  - [0, 1, 0]\n  - [0, 0, 1]\nlens: 25mm\n")
N, W, K = 4, 3, 200
prof = np.arange(N * W * 2, dtype=np.float32).reshape(N, W, 2) * np.float32(0.25)
prof[2, 1, :] = np.nan
np.save(d + "/top/profiles.npy", prof)
np.save(d + "/top/profile_times.npy", np.arange(N, dtype=np.int64) * 2000000 + 10**12)
np.save(d + "/top/profile_positions.npy", np.arange(N, dtype=np.float64) * 0.125)
acc = np.zeros((K, 3), dtype=np.float32)
acc[:, 0] = np.arange(K, dtype=np.float32) * np.float32(0.5)
acc[:, 2] = np.float32(9.81)
np.save(d + "/top/accel.npy", acc)
np.save(d + "/top/accel_times.npy", np.arange(K, dtype=np.int64) * 10000000 + 10**12 - 800000000)
)PY");
    std::string out;
    ASSERT_EQ(
        run(kPython + " " + (tmp.path / "gen.py").string() + " " + (tmp.path / "part").string(),
            out),
        0)
        << out;
    auto rec = read_recording(tmp.path / "part");
    ASSERT_TRUE(rec.ok()) << rec.error().message;
    EXPECT_EQ(rec->part_id, "P-7");
    EXPECT_EQ(rec->captured_at, "2026-11-21T10:15:00Z");
    EXPECT_FALSE(rec->temperature_c.has_value());
    EXPECT_TRUE(rec->warnings.empty());
    ASSERT_EQ(rec->faces.size(), 1u);
    const FaceScan& f = rec->faces[0];
    ASSERT_EQ(f.n_profiles(), 4);
    ASSERT_EQ(f.width, 3);
    ASSERT_EQ(f.n_accel(), 200);
    for (std::int64_t k = 0; k < 4; ++k) {
        EXPECT_EQ(f.profile_times_ns[k], k * 2000000 + 1'000'000'000'000);
        EXPECT_EQ(f.profile_positions_mm[k], static_cast<double>(k) * 0.125);
        for (std::int64_t i = 0; i < 3; ++i) {
            if (k == 2 && i == 1) {
                EXPECT_TRUE(std::isnan(f.x(k, i)) && std::isnan(f.z(k, i)));
                continue;
            }
            EXPECT_EQ(f.x(k, i), static_cast<float>((k * 3 + i) * 2) * 0.25f);
            EXPECT_EQ(f.z(k, i), static_cast<float>((k * 3 + i) * 2 + 1) * 0.25f);
        }
    }
    EXPECT_EQ(f.accel(10), Eigen::Vector3d(5.0, 0.0, static_cast<double>(9.81f)));
    EXPECT_EQ(f.accel_times_ns[199], 199 * 10000000 + 1'000'000'000'000 - 800000000);
    // Geometry of the contract: P = camera_to_world · (x, 0, z, 1)ᵀ + position · scan_direction.
    const Eigen::Vector3d p = f.nominal_world_point(3, 2);
    EXPECT_EQ(p, Eigen::Vector3d(5.5, 0.375, 494.25));
}

TEST(RecordingIo, ValidatorAcceptsWhatWeWrite) {
    const fs::path validator =
        fs::path(HOTGAUGE_SOURCE_DIR "/../shared/tools/validate-recording").lexically_normal();
    if (!fs::exists(validator)) GTEST_SKIP() << "validator not found at " << validator;
    if (!have_numpy()) GTEST_SKIP() << kPython << " with numpy not available";
    TempDir tmp;
    ASSERT_TRUE(write_recording(make_recording(), tmp.path / "part").ok());
    std::string out;
    EXPECT_EQ(
        run(kPython + " " + validator.string() + " " + (tmp.path / "part").string() + " 2>&1", out),
        0)
        << out;
    EXPECT_TRUE(contains(out, "valid hotgauge-recording/1")) << out;

    // The validator is not a rubber stamp: a broken copy is rejected.
    fs::remove(tmp.path / "part" / "side1" / "accel_times.npy");
    EXPECT_EQ(
        run(kPython + " " + validator.string() + " " + (tmp.path / "part").string() + " 2>&1", out),
        1)
        << out;
}

TEST(RecordingIo, PlyHeaderAndData) {
    TempDir tmp;
    const std::vector<Eigen::Vector3d> pts = {{1.5, -2.0, 3.25}, {0.1, 0.2, 0.3}};
    ASSERT_TRUE(hotgauge::io::write_ply(tmp.path / "c.ply", pts).ok());
    const std::string s = slurp(tmp.path / "c.ply");
    const std::string header =
        "ply\nformat binary_little_endian 1.0\ncomment hotgauge world cloud, mm\n"
        "element vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    ASSERT_EQ(s.size(), header.size() + 2 * 3 * sizeof(float));
    EXPECT_EQ(s.substr(0, header.size()), header);
    float v[6];
    std::memcpy(v, s.data() + header.size(), sizeof v);
    EXPECT_EQ(v[0], 1.5f);
    EXPECT_EQ(v[2], 3.25f);
    EXPECT_EQ(v[3], 0.1f);
    EXPECT_EQ(v[5], 0.3f);
    EXPECT_FALSE(hotgauge::io::write_ply(tmp.path / "no" / "dir" / "c.ply", pts).ok());
}

// ---- Contract violations: each error names the file and the problem. ----

class BadRecording : public ::testing::Test {
  protected:
    void SetUp() override {
        dir = tmp.path / "part";
        ASSERT_TRUE(write_recording(make_recording(), dir).ok());
        ASSERT_TRUE(read_recording(dir).ok());
    }
    // Asserts that reading fails with a message starting with `file` + ": " and containing
    // each of `parts`.
    void expect_error(const fs::path& file, std::initializer_list<std::string> parts) {
        auto r = read_recording(dir);
        ASSERT_FALSE(r.ok()) << "accepted a bad recording";
        const std::string& m = r.error().message;
        EXPECT_EQ(m.rfind(file.string() + ": ", 0), 0u) << m;
        for (const auto& p : parts) EXPECT_TRUE(contains(m, p)) << "'" << p << "' not in: " << m;
    }
    void write_face_yaml(const std::string& T, const std::string& s, const std::string& R) {
        dump(dir / "top" / "face.yaml",
             "camera_to_world: " + T + "\nscan_direction: " + s + "\naccel_to_camera: " + R + "\n");
    }
    void replace_in(const fs::path& p, const std::string& from, const std::string& to) {
        std::string s = slurp(p);
        const auto at = s.find(from);
        ASSERT_NE(at, std::string::npos) << from;
        s.replace(at, from.size(), to);
        dump(p, s);
    }
    fs::path top(const char* name) const { return dir / "top" / name; }

    TempDir tmp;
    fs::path dir;
    const std::string I4 = "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]";
    const std::string I3 = "[[1,0,0],[0,1,0],[0,0,1]]";
};

TEST_F(BadRecording, MissingPartYaml) {
    fs::remove(dir / "part.yaml");
    expect_error(dir / "part.yaml", {"missing"});
}

TEST_F(BadRecording, MissingProfiles) {
    fs::remove(top("profiles.npy"));
    expect_error(top("profiles.npy"), {"missing"});
}

TEST_F(BadRecording, MissingFaceYamlAndFaceFolder) {
    fs::remove(top("face.yaml"));
    expect_error(top("face.yaml"), {"missing"});
    fs::remove_all(dir / "side1");
    replace_in(dir / "part.yaml", "\"top\", ", "");
    expect_error(dir / "side1" / "face.yaml", {"missing"});
}

TEST_F(BadRecording, ProfilesAsFloat64) {
    std::vector<double> v(6 * 5 * 2, 1.0);
    ASSERT_TRUE(write_npy(top("profiles.npy"), "<f8", {6, 5, 2}, v.data(), v.size() * 8).ok());
    expect_error(top("profiles.npy"), {"dtype '<f8', expected '<f4'"});
}

TEST_F(BadRecording, TimestampsAsFloat64WithNaN) {
    // NaN timestamps cannot exist in a valid file: timestamps are integers, so the dtype check
    // rejects them.
    std::vector<double> t = {0, 1, std::numeric_limits<double>::quiet_NaN(), 3, 4, 5};
    ASSERT_TRUE(write_npy(top("profile_times.npy"), "<f8", {6}, t.data(), 48).ok());
    expect_error(top("profile_times.npy"), {"dtype '<f8', expected '<i8'"});
}

TEST_F(BadRecording, ProfilesWithThreeColumns) {
    std::vector<float> v(6 * 5 * 3, 1.0f);
    ASSERT_TRUE(write_npy(top("profiles.npy"), "<f4", {6, 5, 3}, v.data(), v.size() * 4).ok());
    expect_error(top("profiles.npy"), {"shape (6, 5, 3), expected (N, W, 2)"});
}

TEST_F(BadRecording, AccelWithWrongRank) {
    std::vector<float> v(12, 1.0f);
    ASSERT_TRUE(write_npy(top("accel.npy"), "<f4", {12}, v.data(), 48).ok());
    expect_error(top("accel.npy"), {"shape (12,), expected (K, 3)"});
}

TEST_F(BadRecording, FortranOrder) {
    replace_in(top("profiles.npy"), "'fortran_order': False", "'fortran_order': True ");
    expect_error(top("profiles.npy"), {"fortran_order is True", "C order"});
}

TEST_F(BadRecording, CountsDisagree) {
    const std::vector<std::int64_t> t = {1, 2, 3, 4, 5};
    ASSERT_TRUE(write_npy(top("profile_times.npy"), "<i8", {5}, t.data(), 40).ok());
    expect_error(top("profile_times.npy"), {"5 entries, expected 6"});
}

TEST_F(BadRecording, AccelCountsDisagree) {
    const std::vector<std::int64_t> t = {1, 2, 3};
    ASSERT_TRUE(write_npy(top("accel_times.npy"), "<i8", {3}, t.data(), 24).ok());
    expect_error(top("accel_times.npy"), {"3 entries, expected"});
}

// Issue 18, finding 5: an inconsistent face was read whole (a 2 GiB profiles.npy: 10 s, 2 GB)
// before the cheap count check failed. The headers are checked first now: a 4 GiB profiles.npy
// (sparse here, so it costs no disk) next to 6 profile times is refused without reading it.
TEST_F(BadRecording, AHugeInconsistentFaceIsRefusedBeforeItsDataIsRead) {
    std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (16777216, 32, 2), }";
    header.append(64 - (10 + header.size() + 1) % 64, ' ');
    header += '\n';
    std::string prelude = "\x93NUMPY\x01";
    prelude += '\0';
    prelude += static_cast<char>(header.size() & 0xFF);
    prelude += static_cast<char>(header.size() >> 8);
    dump(top("profiles.npy"), prelude + header);
    const std::uintmax_t data = std::uintmax_t{16777216} * 32 * 2 * 4;
    fs::resize_file(top("profiles.npy"), prelude.size() + header.size() + data);
    struct rusage before {
    }, after{};
    ::getrusage(RUSAGE_SELF, &before);
    expect_error(top("profile_times.npy"), {"6 entries, expected 16777216"});
    ::getrusage(RUSAGE_SELF, &after);
    EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 256 * 1024) << "kB: the data was read";
}

TEST_F(BadRecording, TruncatedNpy) {
    fs::resize_file(top("profiles.npy"), fs::file_size(top("profiles.npy")) - 7);
    expect_error(top("profiles.npy"), {"truncated data", "needs 240 bytes, file has 233"});
}

TEST_F(BadRecording, NaNInProfilePositions) {
    std::vector<double> p = {0, 1, 2, std::numeric_limits<double>::quiet_NaN(), 4, 5};
    ASSERT_TRUE(write_npy(top("profile_positions.npy"), "<f8", {6}, p.data(), 48).ok());
    expect_error(top("profile_positions.npy"), {"non-finite value", "index 3"});
}

TEST_F(BadRecording, ProfileTimesNotIncreasing) {
    const std::vector<std::int64_t> t = {10, 20, 20, 30, 40, 50};
    ASSERT_TRUE(write_npy(top("profile_times.npy"), "<i8", {6}, t.data(), 48).ok());
    expect_error(top("profile_times.npy"),
                 {"timestamps not strictly increasing", "index 2 has 20 ns after 20 ns"});
}

TEST_F(BadRecording, AccelTimesNotIncreasing) {
    auto r = read_recording(dir);
    ASSERT_TRUE(r.ok());
    std::vector<std::int64_t> t = r->faces[0].accel_times_ns;
    std::swap(t[4], t[5]);
    ASSERT_TRUE(write_npy(top("accel_times.npy"), "<i8", {static_cast<std::int64_t>(t.size())},
                          t.data(), t.size() * 8)
                    .ok());
    expect_error(top("accel_times.npy"), {"timestamps not strictly increasing", "index 5"});
}

TEST_F(BadRecording, CameraToWorldNotOrthonormal) {
    write_face_yaml("[[1,0,0,0],[0,1.001,0,0],[0,0,1,0],[0,0,0,1]]", "[0, 1, 0]", I3);
    expect_error(top("face.yaml"), {"camera_to_world", "not a proper rotation"});
}

TEST_F(BadRecording, CameraToWorldReflection) {
    write_face_yaml("[[1,0,0,0],[0,1,0,0],[0,0,-1,0],[0,0,0,1]]", "[0, 1, 0]", I3);
    expect_error(top("face.yaml"), {"camera_to_world", "not a proper rotation", "det R = -1"});
}

TEST_F(BadRecording, CameraToWorldLastRow) {
    write_face_yaml("[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]]", "[0, 1, 0]", I3);
    expect_error(top("face.yaml"), {"camera_to_world last row must be [0, 0, 0, 1]"});
}

TEST_F(BadRecording, CameraToWorldWrongSize) {
    write_face_yaml("[[1,0,0],[0,1,0],[0,0,1]]", "[0, 1, 0]", I3);
    expect_error(top("face.yaml"), {"'camera_to_world' must be a 4x4 list of rows"});
}

TEST_F(BadRecording, AccelToCameraNotOrthonormal) {
    write_face_yaml(I4, "[0, 1, 0]", "[[1,0.01,0],[0,1,0],[0,0,1]]");
    expect_error(top("face.yaml"), {"accel_to_camera is not a proper rotation"});
}

TEST_F(BadRecording, ScanDirectionNotUnit) {
    write_face_yaml(I4, "[0, 1.00001, 0]", I3);
    expect_error(top("face.yaml"), {"scan_direction is not a unit vector", "1.00001"});
}

TEST_F(BadRecording, NonNumericMatrixEntry) {
    write_face_yaml(I4, "[0, \"1\", 0]", I3);
    expect_error(top("face.yaml"), {"'scan_direction' element [1] is not a number", "line 2"});
}

TEST_F(BadRecording, MissingFaceKey) {
    dump(top("face.yaml"), "camera_to_world: " + I4 + "\naccel_to_camera: " + I3 + "\n");
    expect_error(top("face.yaml"), {"missing key 'scan_direction'"});
}

TEST_F(BadRecording, UnknownFormatVersion) {
    replace_in(dir / "part.yaml", "hotgauge-recording/1", "hotgauge-recording/2");
    expect_error(dir / "part.yaml", {"unknown format version 'hotgauge-recording/2', expected "
                                     "'hotgauge-recording/1'"});
}

TEST_F(BadRecording, MissingPartKeys) {
    replace_in(dir / "part.yaml", "recipe:", "recipe_name:");
    expect_error(dir / "part.yaml", {"missing key 'recipe'"});
}

TEST_F(BadRecording, TemperatureNotANumber) {
    replace_in(dir / "part.yaml", "temperature_c: ", "temperature_c: hot # ");
    expect_error(dir / "part.yaml", {"'temperature_c' must be a finite number, found 'hot'"});
}

TEST_F(BadRecording, BadFaceList) {
    replace_in(dir / "part.yaml", "faces: [\"top\", \"side1\"]", "faces: []");
    expect_error(dir / "part.yaml", {"'faces' must be a non-empty list"});
    replace_in(dir / "part.yaml", "faces: []", "faces: [top, \"../x\"]");
    expect_error(dir / "part.yaml", {"face name '../x' is not a plain folder name"});
    replace_in(dir / "part.yaml", "faces: [top, \"../x\"]", "faces: [top, side1, top]");
    expect_error(dir / "part.yaml", {"face 'top' is listed twice"});
}

TEST_F(BadRecording, YamlSyntaxErrorNamesLine) {
    dump(dir / "part.yaml",
         "format: hotgauge-recording/1\npart_id: \"H-1\"\nrecipe: [hub-a\ncaptured_at: x\n");
    auto r = read_recording(dir);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(
        r.error().message.rfind((dir / "part.yaml").string() + ": YAML syntax error at line ", 0),
        0u)
        << r.error().message;

    ASSERT_TRUE(write_recording(make_recording(), dir).ok());
    dump(top("face.yaml"), "camera_to_world: " + I4 + "\nscan_direction: [0, 1, 0]]\n");
    expect_error(top("face.yaml"), {"YAML syntax error at line 2"});
}

TEST_F(BadRecording, NpyVersion2Header) {
    const std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (6, 5, 2), }\n";
    std::string s = "\x93NUMPY";
    s += '\x02';
    s += '\x00';
    const auto n = static_cast<std::uint32_t>(header.size());
    for (int i = 0; i < 4; ++i) s += static_cast<char>((n >> (8 * i)) & 0xFF);
    s += header + std::string(240, '\0');
    dump(top("profiles.npy"), s);
    expect_error(top("profiles.npy"),
                 {".npy format version 2.0, recording format v1 requires 1.0"});
}

TEST_F(BadRecording, UnknownKeysAreIgnored) {
    replace_in(dir / "part.yaml",
               "faces:", "operator: \"A. N. Other\"\nline_speed: {a: 1}\nfaces:");
    replace_in(top("face.yaml"), "scan_direction:", "lens_mm: 25\nscan_direction:");
    auto r = read_recording(dir);
    EXPECT_TRUE(r.ok()) << r.error().message;
}

// Random corruption of every file: read_recording returns (ok or Error) and never throws.
TEST_F(BadRecording, NeverThrowsOnCorruptFiles) {
    std::mt19937 rng(12345);
    for (const fs::path& p :
         {dir / "part.yaml", top("face.yaml"), top("profiles.npy"), top("accel_times.npy")}) {
        const std::string good = slurp(p);
        std::uniform_int_distribution<std::size_t> pos(0,
                                                       std::min<std::size_t>(good.size(), 140) - 1);
        std::uniform_int_distribution<int> byte(0, 255);
        for (int it = 0; it < 300; ++it) {
            std::string bad = good;
            for (int j = 0; j <= it % 3; ++j) bad[pos(rng)] = static_cast<char>(byte(rng));
            if (it % 10 == 0) bad.resize(pos(rng));
            dump(p, bad);
            EXPECT_NO_THROW({
                auto r = read_recording(dir);
                if (!r.ok()) {
                    EXPECT_FALSE(r.error().message.empty());
                }
            });
        }
        dump(p, good);
    }
    EXPECT_TRUE(read_recording(dir).ok());
}

// ---- The writer refuses what the reader would reject, and writes nothing. ----

TEST(RecordingIoWrite, RejectsInvalidRecordings) {
    struct Case {
        const char* what;
        void (*spoil)(Recording&);
        const char* file;
        const char* expect;
    };
    const std::vector<Case> cases = {
        {"rotation", [](Recording& r) { r.faces[0].T_world_camera.linear()(0, 0) = 1.01; },
         "top/face.yaml", "camera_to_world rotation part is not a proper rotation"},
        {"accel rotation", [](Recording& r) { r.faces[1].R_camera_accel *= -1.0; },
         "side1/face.yaml", "accel_to_camera is not a proper rotation"},
        {"scan", [](Recording& r) { r.faces[0].scan_direction *= 2.0; }, "top/face.yaml",
         "scan_direction is not a unit vector"},
        {"times",
         [](Recording& r) { r.faces[0].profile_times_ns[4] = r.faces[0].profile_times_ns[3]; },
         "top/profile_times.npy", "not strictly increasing: index 4"},
        {"accel times", [](Recording& r) { r.faces[0].accel_times_ns[1] = 0; },
         "top/accel_times.npy", "not strictly increasing: index 1"},
        {"size", [](Recording& r) { r.faces[1].profiles_mm.pop_back(); }, "side1/profiles.npy",
         "values, expected N*W*2 = 24"},
        {"accel size", [](Recording& r) { r.faces[0].accel_mps2.push_back(1.0f); }, "top/accel.npy",
         "expected K*3"},
        {"positions size", [](Recording& r) { r.faces[0].profile_positions_mm.pop_back(); },
         "top/profile_positions.npy", "5 entries, expected 6"},
        {"nan position",
         [](Recording& r) {
             r.faces[0].profile_positions_mm[2] = std::numeric_limits<double>::infinity();
         },
         "top/profile_positions.npy", "non-finite value"},
        {"name", [](Recording& r) { r.faces[1].name = "a/b"; }, "part.yaml",
         "not a plain folder name"},
        {"duplicate", [](Recording& r) { r.faces[1].name = "top"; }, "part.yaml", "listed twice"},
        {"no faces", [](Recording& r) { r.faces.clear(); }, "part.yaml", "at least one face"},
        {"temperature", [](Recording& r) { r.temperature_c = std::nan(""); }, "part.yaml",
         "temperature_c must be finite"},
    };
    for (const auto& c : cases) {
        SCOPED_TRACE(c.what);
        TempDir tmp;
        Recording rec = make_recording();
        c.spoil(rec);
        auto r = write_recording(rec, tmp.path / "part");
        ASSERT_FALSE(r.ok());
        EXPECT_EQ(r.error().message.rfind((tmp.path / "part" / c.file).string() + ": ", 0), 0u)
            << r.error().message;
        EXPECT_TRUE(contains(r.error().message, c.expect)) << r.error().message;
        EXPECT_FALSE(fs::exists(tmp.path / "part")) << "wrote something";
    }
}
