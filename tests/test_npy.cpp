// .npy v1.0 reader/writer: round trips, header parsing variants, byte-identity with numpy.save,
// and every rejection path naming the file and the problem.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "hotgauge/io/npy.hpp"
#include "temp_dir.hpp"

namespace fs = std::filesystem;
using hotgauge::io::NpyArray;
using hotgauge::io::read_npy;
using hotgauge::io::write_npy;

namespace {

// The system Python with Debian's python3-numpy (tests/CMakeLists.txt may override it).
#ifdef HOTGAUGE_PYTHON
const std::string kPython = HOTGAUGE_PYTHON;
#else
const std::string kPython = "/usr/bin/python3";
#endif

using hotgauge::test::TempDir;

std::vector<unsigned char> slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void dump(const fs::path& p, const std::string& bytes) {
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out << bytes;
}

// A raw .npy file with the given version and header text (no padding rules applied).
std::string raw_npy(int major, int minor, const std::string& header, const std::string& data) {
    std::string s = "\x93NUMPY";
    s += static_cast<char>(major);
    s += static_cast<char>(minor);
    const std::size_t n = header.size();
    s += static_cast<char>(n & 0xFF);
    s += static_cast<char>((n >> 8) & 0xFF);
    if (major >= 2) {  // v2/v3: uint32 header length
        s += static_cast<char>((n >> 16) & 0xFF);
        s += static_cast<char>((n >> 24) & 0xFF);
    }
    return s + header + data;
}

// Runs a command; returns its exit status and fills `out` with its stdout.
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

}  // namespace

TEST(Npy, RoundTripFloat3dWithNaN) {
    TempDir tmp;
    std::vector<float> v(3 * 4 * 2);
    for (std::size_t i = 0; i < v.size(); ++i) v[i] = static_cast<float>(i) * 0.25f - 1.0f;
    v[5] = std::numeric_limits<float>::quiet_NaN();
    v[6] = -0.0f;
    const fs::path p = tmp.path / "a.npy";
    ASSERT_TRUE(write_npy(p, "<f4", {3, 4, 2}, v.data(), v.size() * sizeof(float)).ok());
    auto r = read_npy(p);
    ASSERT_TRUE(r.ok()) << r.error().message;
    EXPECT_EQ(r->descr, "<f4");
    EXPECT_FALSE(r->fortran_order);
    EXPECT_EQ(r->shape, (std::vector<std::int64_t>{3, 4, 2}));
    ASSERT_EQ(r->data.size(), v.size() * sizeof(float));
    EXPECT_EQ(std::memcmp(r->data.data(), v.data(), r->data.size()), 0);
}

TEST(Npy, RoundTripEmptyAndScalar) {
    TempDir tmp;
    ASSERT_TRUE(write_npy(tmp.path / "e.npy", "<f4", {0, 3}, nullptr, 0).ok());
    auto e = read_npy(tmp.path / "e.npy");
    ASSERT_TRUE(e.ok()) << e.error().message;
    EXPECT_EQ(e->shape, (std::vector<std::int64_t>{0, 3}));
    EXPECT_TRUE(e->data.empty());

    ASSERT_TRUE(write_npy(tmp.path / "e1.npy", "<i8", {0}, nullptr, 0).ok());
    auto e1 = read_npy(tmp.path / "e1.npy");
    ASSERT_TRUE(e1.ok()) << e1.error().message;
    EXPECT_EQ(e1->shape, (std::vector<std::int64_t>{0}));

    const double x = 3.5;
    ASSERT_TRUE(write_npy(tmp.path / "s.npy", "<f8", {}, &x, sizeof x).ok());
    auto s = read_npy(tmp.path / "s.npy");
    ASSERT_TRUE(s.ok()) << s.error().message;
    EXPECT_TRUE(s->shape.empty());
    ASSERT_EQ(s->data.size(), sizeof x);
    double y = 0;
    std::memcpy(&y, s->data.data(), sizeof y);
    EXPECT_EQ(y, x);
}

TEST(Npy, HeaderIsVersion1AndDataAlignedTo64) {
    TempDir tmp;
    const std::vector<std::vector<std::int64_t>> shapes = {
        {}, {7}, {0, 3}, {3, 2048, 2}, {123456789012, 0, 5}, {1, 1, 1, 1, 1, 1, 1, 1}};
    for (const auto& shape : shapes) {
        const fs::path p = tmp.path / "h.npy";
        std::int64_t n = 1;
        for (auto d : shape) n *= d;
        std::vector<std::int64_t> data(static_cast<std::size_t>(n));
        ASSERT_TRUE(write_npy(p, "<i8", shape, data.data(), data.size() * 8).ok());
        const auto bytes = slurp(p);
        ASSERT_GE(bytes.size(), 10u);
        EXPECT_EQ(std::memcmp(bytes.data(), "\x93NUMPY\x01\x00", 8), 0);
        const std::size_t hlen = bytes[8] | (bytes[9] << 8);
        EXPECT_EQ((10 + hlen) % 64, 0u) << "shape rank " << shape.size();
        EXPECT_EQ(bytes[10 + hlen - 1], '\n');
        EXPECT_EQ(bytes.size(), 10 + hlen + data.size() * 8);
    }
}

TEST(Npy, ParsesHeaderVariants) {
    TempDir tmp;
    const std::string six_floats(24, '\0');
    struct Case {
        std::string header;
        std::vector<std::int64_t> shape;
        std::string descr;
        bool fortran;
        std::size_t bytes;
    };
    const std::vector<Case> cases = {
        {"{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }\n", {2, 3}, "<f4", false, 24},
        {"{'shape': (6,), 'fortran_order': False, 'descr': '<f4'}\n", {6}, "<f4", false, 24},
        {"{\"fortran_order\":True,\"shape\":(3,2),\"descr\":\"<f4\"}   \n",
         {3, 2},
         "<f4",
         true,
         24},
        {"{ 'descr' : '<f4' ,\n 'fortran_order' : False , 'shape' : ( 2L , 3L , ) , }",
         {2, 3},
         "<f4",
         false,
         24},
        {"{'descr': '<f8', 'fortran_order': False, 'shape': (0, 3), }\n", {0, 3}, "<f8", false, 0},
        {"{'descr': '<f8', 'fortran_order': False, 'shape': (), }\n", {}, "<f8", false, 8},
        {"{'descr': '|u1', 'fortran_order': False, 'shape': (24,), }\n", {24}, "|u1", false, 24},
    };
    for (const auto& c : cases) {
        const fs::path p = tmp.path / "v.npy";
        dump(p, raw_npy(1, 0, c.header, six_floats.substr(0, c.bytes)));
        auto r = read_npy(p);
        ASSERT_TRUE(r.ok()) << c.header << " -> " << r.error().message;
        EXPECT_EQ(r->shape, c.shape) << c.header;
        EXPECT_EQ(r->descr, c.descr) << c.header;
        EXPECT_EQ(r->fortran_order, c.fortran) << c.header;
        EXPECT_EQ(r->data.size(), c.bytes) << c.header;
    }
}

TEST(Npy, RejectsVersion2And3) {
    TempDir tmp;
    const std::string h = "{'descr': '<f4', 'fortran_order': False, 'shape': (1,), }\n";
    for (int major : {2, 3}) {
        const fs::path p = tmp.path / "v2.npy";
        dump(p, raw_npy(major, 0, h, std::string(4, '\0')));
        auto r = read_npy(p);
        ASSERT_FALSE(r.ok());
        EXPECT_EQ(r.error().message, p.string() + ": .npy format version " + std::to_string(major) +
                                         ".0, recording format v1 requires 1.0");
    }
}

TEST(Npy, RejectsTruncatedDataWithByteCounts) {
    TempDir tmp;
    std::vector<float> v(24, 1.0f);
    const fs::path p = tmp.path / "t.npy";
    ASSERT_TRUE(write_npy(p, "<f4", {4, 3, 2}, v.data(), 96).ok());
    fs::resize_file(p, fs::file_size(p) - 5);
    auto r = read_npy(p);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find(p.string() + ": truncated data"), std::string::npos)
        << r.error().message;
    EXPECT_NE(r.error().message.find("needs 96 bytes, file has 91"), std::string::npos)
        << r.error().message;

    // Cut inside the header.
    fs::resize_file(p, 40);
    r = read_npy(p);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("truncated .npy header"), std::string::npos)
        << r.error().message;
}

TEST(Npy, RejectsTrailingData) {
    TempDir tmp;
    const fs::path p = tmp.path / "x.npy";
    dump(p, raw_npy(1, 0, "{'descr': '<f4', 'fortran_order': False, 'shape': (1,), }\n",
                    std::string(6, '\0')));
    auto r = read_npy(p);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("trailing data"), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find("needs 4 bytes, file has 6"), std::string::npos)
        << r.error().message;
}

TEST(Npy, RejectsMalformedFiles) {
    TempDir tmp;
    const fs::path p = tmp.path / "m.npy";
    struct Case {
        std::string file;
        std::string expect;
    };
    const std::vector<Case> cases = {
        {"PK\x03\x04 not numpy at all", "not a .npy file"},
        {raw_npy(1, 0, "{'descr': '<f4', 'shape': (1,), }\n", "1234"), "no 'fortran_order'"},
        {raw_npy(1, 0, "{'descr': '<f4', 'fortran_order': False, }\n", "1234"), "no 'shape'"},
        {raw_npy(1, 0, "{'fortran_order': False, 'shape': (1,), }\n", "1234"), "no 'descr'"},
        {raw_npy(1, 0, "{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (1,), }\n",
                 "1234"),
         "structured dtypes"},
        {raw_npy(1, 0, "{'descr': '<f4', 'fortran_order': 0, 'shape': (1,), }\n", "1234"),
         "'fortran_order' is not True or False"},
        {raw_npy(1, 0, "{'descr': '<f4', 'fortran_order': False, 'shape': (-1,), }\n", "1234"),
         "'shape' is not a tuple"},
        {raw_npy(1, 0, "{'descr': '<f4', 'fortran_order': False, 'shape': (1), }\n", "1234"),
         "'shape' is not a tuple"},
        {raw_npy(1, 0, "{'descr': '<f4', 'fortran_order': False, 'shape': (1,), 'x': 1}\n", "1234"),
         "unexpected key 'x'"},
        {raw_npy(1, 0, "{'descr': 'O', 'fortran_order': False, 'shape': (1,), }\n", "1234"),
         "unsupported dtype 'O'"},
        {raw_npy(1, 0, "{'descr': '<f4', 'fortran_order': False, 'shape': (1,), } junk\n", "1234"),
         "unexpected text after the header dict"},
        {raw_npy(1, 1, "{'descr': '<f4', 'fortran_order': False, 'shape': (1,), }\n", "1234"),
         ".npy format version 1.1, recording format v1 requires 1.0"},
        {raw_npy(1, 0,
                 "{'descr': '<f8', 'fortran_order': False, 'shape': (4294967296, 4294967296, "
                 "4294967296), }\n",
                 ""),
         "too large"},
    };
    for (const auto& c : cases) {
        dump(p, c.file);
        auto r = read_npy(p);
        ASSERT_FALSE(r.ok()) << c.expect;
        EXPECT_EQ(r.error().message.rfind(p.string() + ": ", 0), 0u) << r.error().message;
        EXPECT_NE(r.error().message.find(c.expect), std::string::npos)
            << "expected '" << c.expect << "' in: " << r.error().message;
    }
    auto missing = read_npy(tmp.path / "nope.npy");
    ASSERT_FALSE(missing.ok());
    EXPECT_EQ(missing.error().message, (tmp.path / "nope.npy").string() + ": missing");
}

// What every file reader reads through (io::read_bytes): a folder or a FIFO is no file, and the
// FIFO is refused at once, not after a writer comes; a large file reads whole.
TEST(Npy, OnlyRegularFilesAreRead) {
    TempDir tmp;
    ASSERT_EQ(::mkfifo((tmp.path / "fifo.npy").c_str(), 0600), 0);
    std::filesystem::create_directory(tmp.path / "dir.npy");
    for (const char* name : {"fifo.npy", "dir.npy"}) {
        auto r = read_npy(tmp.path / name);
        ASSERT_FALSE(r.ok());
        EXPECT_EQ(r.error().message, (tmp.path / name).string() + ": not a regular file");
    }
    std::vector<float> big(300'000);
    for (std::size_t i = 0; i < big.size(); ++i) big[i] = static_cast<float>(i) * 0.5f;
    ASSERT_TRUE(write_npy(tmp.path / "big.npy", "<f4", {300'000}, big.data(), big.size() * 4).ok());
    auto back = read_npy(tmp.path / "big.npy");
    ASSERT_TRUE(back.ok()) << back.error().message;
    ASSERT_EQ(back->data.size(), big.size() * 4);
    EXPECT_EQ(std::memcmp(back->data.data(), big.data(), back->data.size()), 0);
}

TEST(Npy, WriteRejectsSizeMismatch) {
    TempDir tmp;
    std::vector<float> v(5);
    auto r = write_npy(tmp.path / "w.npy", "<f4", {2, 3}, v.data(), v.size() * sizeof(float));
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.error().message.find("needs 24 bytes, got 20"), std::string::npos)
        << r.error().message;
    EXPECT_FALSE(fs::exists(tmp.path / "w.npy"));
}

// Our writer produces exactly the bytes numpy.save produces (header, padding, data), and
// numpy.load reads our files back to the same values.
TEST(Npy, ByteIdenticalToNumpySave) {
    if (!have_numpy()) GTEST_SKIP() << kPython << " with numpy not available";
    TempDir tmp;
    const std::string script = R"PY(
import sys, numpy as np
d = sys.argv[1]
a = (np.arange(3 * 5 * 2, dtype="<f4").reshape(3, 5, 2) * np.float32(0.5) - np.float32(3))
a[1, 2, 0] = np.nan
np.save(d + "/np_prof.npy", a)
np.save(d + "/np_empty.npy", np.zeros((0, 3), dtype="<f4"))
np.save(d + "/np_times.npy", np.array([-5, 0, 7, 2**62], dtype="<i8"))
np.save(d + "/np_scalar.npy", np.array(2.25, dtype="<f8"))
np.save(d + "/np_big.npy", np.zeros((1234567, 0, 2), dtype="<f8"))
np.save(d + "/np_rank16.npy", np.full((1,) * 16, 1.5, dtype="<f8"))  # growth padding matters
)PY";
    dump(tmp.path / "gen.py", script);
    std::string out;
    ASSERT_EQ(run(kPython + " " + (tmp.path / "gen.py").string() + " " + tmp.path.string(), out), 0)
        << out;

    std::vector<float> prof(30);
    for (std::size_t i = 0; i < prof.size(); ++i) prof[i] = static_cast<float>(i) * 0.5f - 3.0f;
    prof[(1 * 5 + 2) * 2] = std::numeric_limits<float>::quiet_NaN();
    const std::vector<std::int64_t> times = {-5, 0, 7, std::int64_t{1} << 62};
    const double scalar = 2.25, one_and_half = 1.5;
    ASSERT_TRUE(write_npy(tmp.path / "hg_prof.npy", "<f4", {3, 5, 2}, prof.data(), 120).ok());
    ASSERT_TRUE(write_npy(tmp.path / "hg_empty.npy", "<f4", {0, 3}, nullptr, 0).ok());
    ASSERT_TRUE(write_npy(tmp.path / "hg_times.npy", "<i8", {4}, times.data(), 32).ok());
    ASSERT_TRUE(write_npy(tmp.path / "hg_scalar.npy", "<f8", {}, &scalar, 8).ok());
    ASSERT_TRUE(write_npy(tmp.path / "hg_big.npy", "<f8", {1234567, 0, 2}, nullptr, 0).ok());
    ASSERT_TRUE(write_npy(tmp.path / "hg_rank16.npy", "<f8", std::vector<std::int64_t>(16, 1),
                          &one_and_half, 8)
                    .ok());
    for (const char* name : {"prof", "empty", "times", "scalar", "big", "rank16"}) {
        const auto ours = slurp(tmp.path / (std::string("hg_") + name + ".npy"));
        const auto theirs = slurp(tmp.path / (std::string("np_") + name + ".npy"));
        EXPECT_EQ(ours, theirs) << name << ": our bytes differ from numpy.save's";
        // And numpy's file reads back through our reader to the same payload.
        auto r = read_npy(tmp.path / (std::string("np_") + name + ".npy"));
        ASSERT_TRUE(r.ok()) << r.error().message;
    }
    auto r = read_npy(tmp.path / "np_prof.npy");
    ASSERT_TRUE(r.ok());
    ASSERT_EQ(r->data.size(), 120u);
    EXPECT_EQ(std::memcmp(r->data.data(), prof.data(), 120), 0);
}
