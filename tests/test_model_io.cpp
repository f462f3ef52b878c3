// Model files (docs/model-file.md): bit-exact round trips and a clear error for every kind of bad
// file; mesh and scan sources: samples on a known cube with outward normals, PCA normals of a
// plane, in files written here byte by byte and in files PCL and VTK wrote (binary_compressed
// PCD, big-endian PLY).
#include <gtest/gtest.h>
#include <pcl/PCLPointCloud2.h>
#include <pcl/io/pcd_io.h>
#include <unistd.h>
#include <vtkCellArray.h>
#include <vtkNew.h>
#include <vtkPLYWriter.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "hotgauge/io/recipe.hpp"
#include "hotgauge/match/model.hpp"
#include "hotgauge/model/model_io.hpp"
#include "hotgauge/model/surface_io.hpp"

namespace fs = std::filesystem;
using hotgauge::match::Model;
using hotgauge::model::read_mesh_samples;
using hotgauge::model::read_model;
using hotgauge::model::read_scan_samples;
using hotgauge::model::SurfaceSamples;
using hotgauge::model::write_model;

namespace {

// `hotgauge model build --mesh|--scan FILE` on a file the test wrote, when ctest names the tool
// (HOTGAUGE_CLI, ctest model_build_cli_pcl_files: the release build; the unit run and the
// sanitizer build, which has no tool, test the readers alone). Returns what it printed.
std::string model_build(const char* option, const std::filesystem::path& file) {
    const char* cli = std::getenv("HOTGAUGE_CLI");
    if (!cli) return "no HOTGAUGE_CLI";
    const auto out = file.string() + ".hgm", log = file.string() + ".out";
    const std::string cmd = std::string(cli) + " model build " + option + " " + file.string() +
                            " --sampling-mm 2 --out " + out + " > " + log + " 2>&1";
    const int rc = std::system(cmd.c_str());
    std::ifstream in(log);
    std::stringstream text;
    text << in.rdbuf();
    EXPECT_EQ(rc, 0) << cmd << "\n" << text.str();
    EXPECT_TRUE(std::filesystem::exists(out)) << text.str();
    return text.str();
}

using Bytes = std::vector<unsigned char>;

class TempDir : public ::testing::Test {
  protected:
    void SetUp() override {
        dir_ = fs::temp_directory_path() /
               ("hotgauge_model_io_" + std::to_string(::getpid()) + "_" +
                ::testing::UnitTest::GetInstance()->current_test_info()->name());
        fs::remove_all(dir_);
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }
    fs::path path(const std::string& name) const { return dir_ / name; }

    fs::path dir_;
};

Bytes read_all(const fs::path& p) {
    std::ifstream f(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(f), {}};
}

void write_all(const fs::path& p, const Bytes& b) {
    std::ofstream(p, std::ios::binary | std::ios::trunc)
        .write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}

void write_text(const fs::path& p, const std::string& s) {
    std::ofstream(p, std::ios::binary | std::ios::trunc) << s;
}

Model recipe_model(double sampling_mm = 5.0) {
    auto recipe = hotgauge::io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
    EXPECT_TRUE(recipe) << recipe.error().message;
    hotgauge::match::ModelConfig config;
    config.sampling_mm = sampling_mm;
    auto m = hotgauge::match::model_from_recipe(*recipe, config);
    EXPECT_TRUE(m) << m.error().message;
    return *m;
}

// ---- byte-level helpers of the documented layout (docs/model-file.md) ----

std::uint64_t fnv1a64(const Bytes& b, std::size_t n) {
    std::uint64_t h = 0xcbf29ce484222325ull;
    for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 0x100000001b3ull;
    return h;
}

void put_le(Bytes& b, std::size_t at, std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) b[at + i] = static_cast<unsigned char>(v >> (8 * i));
}

// Recomputes the trailing checksum after an edit, so that the reader gets past it.
void reseal(Bytes& b) { put_le(b, b.size() - 8, fnv1a64(b, b.size() - 8), 8); }

// Offset of the first reference index (after name, source, config, flag, diameter, step,
// points, normals, refs count).
std::size_t refs_offset(const Model& m) {
    return 20 + 8 + m.name.size() + 8 + m.source.size() + 24 + 1 + 16 + 8 + 12 * m.points.size() +
           8 + 12 * m.normals.size() + 8;
}

// ---- field-by-field, bit-exact comparison ----

template <class T>
bool same_bits(const T& a, const T& b) {
    return std::memcmp(&a, &b, sizeof(T)) == 0;
}

void expect_same_vectors(const std::vector<Eigen::Vector3f>& a,
                         const std::vector<Eigen::Vector3f>& b, const char* what) {
    ASSERT_EQ(a.size(), b.size()) << what;
    for (std::size_t i = 0; i < a.size(); ++i)
        for (int k = 0; k < 3; ++k)
            ASSERT_TRUE(same_bits(a[i][k], b[i][k])) << what << "[" << i << "]";
}

void expect_same_model(const Model& a, const Model& b) {
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.source, b.source);
    EXPECT_TRUE(same_bits(a.config.sampling_mm, b.config.sampling_mm));
    EXPECT_TRUE(same_bits(a.config.distance_step_mm, b.config.distance_step_mm));
    EXPECT_EQ(a.config.angle_bins, b.config.angle_bins);
    EXPECT_EQ(a.config.alpha_bins, b.config.alpha_bins);
    EXPECT_EQ(a.axisymmetric, b.axisymmetric);
    EXPECT_TRUE(same_bits(a.diameter_mm, b.diameter_mm));
    EXPECT_TRUE(same_bits(a.step_mm, b.step_mm));
    expect_same_vectors(a.points, b.points, "points");
    expect_same_vectors(a.normals, b.normals, "normals");
    EXPECT_EQ(a.refs, b.refs);
    ASSERT_EQ(a.profile.size(), b.profile.size());
    for (std::size_t i = 0; i < a.profile.size(); ++i) {
        EXPECT_EQ(a.profile[i].wall, b.profile[i].wall);
        EXPECT_TRUE(same_bits(a.profile[i].r0, b.profile[i].r0));
        EXPECT_TRUE(same_bits(a.profile[i].z0, b.profile[i].z0));
        EXPECT_TRUE(same_bits(a.profile[i].r1, b.profile[i].r1));
        EXPECT_TRUE(same_bits(a.profile[i].z1, b.profile[i].z1));
    }
    expect_same_vectors(a.dense_points, b.dense_points, "dense_points");
    expect_same_vectors(a.dense_normals, b.dense_normals, "dense_normals");
    EXPECT_EQ(a.key_begin, b.key_begin);
    ASSERT_EQ(a.entries.size(), b.entries.size());
    for (std::size_t i = 0; i < a.entries.size(); ++i) {
        ASSERT_EQ(a.entries[i].ref, b.entries[i].ref) << i;
        ASSERT_TRUE(same_bits(a.entries[i].alpha, b.entries[i].alpha)) << i;
    }
}

// ---- a closed cube [lo, lo + size]³ as a mesh: 8 vertices, 6 outward quads ----

const Eigen::Vector3d kCubeLo(1.0, -2.0, 3.0);
constexpr double kCubeSize = 10.0;

std::vector<Eigen::Vector3d> cube_vertices() {
    std::vector<Eigen::Vector3d> v;
    for (int i = 0; i < 8; ++i)
        v.push_back(kCubeLo + kCubeSize * Eigen::Vector3d(i & 1, (i >> 1) & 1, (i >> 2) & 1));
    return v;
}

// Counter-clockwise seen from outside.
const std::vector<std::array<int, 4>> kCubeQuads = {
    {0, 2, 3, 1},  // z = lo, normal −z
    {4, 5, 7, 6},  // z = hi, +z
    {0, 1, 5, 4},  // y = lo, −y
    {2, 6, 7, 3},  // y = hi, +y
    {0, 4, 6, 2},  // x = lo, −x
    {1, 3, 7, 5},  // x = hi, +x
};

std::vector<std::array<int, 3>> cube_triangles() {
    std::vector<std::array<int, 3>> t;
    for (const auto& q : kCubeQuads) {
        t.push_back({q[0], q[1], q[2]});
        t.push_back({q[0], q[2], q[3]});
    }
    return t;
}

std::string cube_ply_ascii_quads() {
    std::ostringstream s;
    s << "ply\nformat ascii 1.0\ncomment a cube\nelement vertex 8\nproperty float x\n"
         "property float y\nproperty float z\nelement face 6\n"
         "property list uchar int vertex_indices\nend_header\n";
    for (const auto& v : cube_vertices()) s << v.x() << ' ' << v.y() << ' ' << v.z() << '\n';
    for (const auto& q : kCubeQuads)
        s << "4 " << q[0] << ' ' << q[1] << ' ' << q[2] << ' ' << q[3] << '\n';
    return s.str();
}

template <class T>
void append(Bytes& b, T v) {
    const auto* p = reinterpret_cast<const unsigned char*>(&v);
    b.insert(b.end(), p, p + sizeof(T));
}

// Binary PLY of triangles with double coordinates, an extra per-vertex property, uint counts
// and uint indices, and an extra face property: the reader must skip what it does not use.
// (PCL's PLYReader reads face lists with a uchar or uint count, not int.)
Bytes cube_ply_binary() {
    const std::string header =
        "ply\nformat binary_little_endian 1.0\nelement vertex 8\nproperty double x\n"
        "property double y\nproperty double z\nproperty uchar red\nelement face 12\n"
        "property list uint uint vertex_indices\nproperty float quality\nend_header\n";
    Bytes b(header.begin(), header.end());
    for (const auto& v : cube_vertices()) {
        append(b, v.x());
        append(b, v.y());
        append(b, v.z());
        append(b, std::uint8_t{200});
    }
    for (const auto& t : cube_triangles()) {
        append(b, std::uint32_t{3});
        for (int i : t) append(b, static_cast<std::uint32_t>(i));
        append(b, 1.0f);
    }
    return b;
}

std::string cube_stl_ascii() {
    const auto v = cube_vertices();
    std::ostringstream s;
    s << "solid cube made by hand\n";
    for (const auto& t : cube_triangles()) {
        s << "  facet normal 0 0 0\n    outer loop\n";  // winding, not the stored normal, counts
        for (int i : t)
            s << "      vertex " << v[i].x() << ' ' << v[i].y() << ' ' << v[i].z() << '\n';
        s << "    endloop\n  endfacet\n";
    }
    s << "endsolid cube made by hand\n";
    return s.str();
}

Bytes cube_stl_binary() {
    Bytes b(80, ' ');
    const std::string head = "solid but binary";  // a header that starts like ascii STL
    std::copy(head.begin(), head.end(), b.begin());
    const auto v = cube_vertices();
    const auto tris = cube_triangles();
    append(b, static_cast<std::uint32_t>(tris.size()));
    for (const auto& t : tris) {
        for (int k = 0; k < 3; ++k) append(b, 0.0f);
        for (int i : t)
            for (int k = 0; k < 3; ++k) append(b, static_cast<float>(v[i][k]));
        append(b, std::uint16_t{0});
    }
    return b;
}

// Every sample lies on the cube face its normal names, the normals are the outward unit axes,
// the count is area / spacing² within 10 %, and the faces share the samples by area.
void expect_cube_samples(const SurfaceSamples& s, double spacing_mm) {
    const double expected = 6 * kCubeSize * kCubeSize / (spacing_mm * spacing_mm);
    ASSERT_EQ(s.points.size(), s.normals.size());
    EXPECT_NEAR(static_cast<double>(s.points.size()), expected, 0.1 * expected);
    std::array<int, 6> per_face{};
    for (std::size_t i = 0; i < s.points.size(); ++i) {
        const Eigen::Vector3d p = s.points[i].cast<double>(), n = s.normals[i].cast<double>();
        int axis = 0;
        n.cwiseAbs().maxCoeff(&axis);
        Eigen::Vector3d outward = Eigen::Vector3d::Zero();
        outward[axis] = n[axis] > 0 ? 1 : -1;
        ASSERT_LT((n - outward).norm(), 1e-6) << "sample " << i << " normal " << n.transpose();
        const double plane = kCubeLo[axis] + (n[axis] > 0 ? kCubeSize : 0.0);
        ASSERT_LT(std::abs(p[axis] - plane), 1e-4) << "sample " << i << " at " << p.transpose();
        for (int k = 0; k < 3; ++k) {
            ASSERT_GE(p[k], kCubeLo[k] - 1e-4) << i;
            ASSERT_LE(p[k], kCubeLo[k] + kCubeSize + 1e-4) << i;
        }
        ++per_face[2 * axis + (n[axis] > 0)];
    }
    for (int f = 0; f < 6; ++f) EXPECT_NEAR(per_face[f], expected / 6, 0.1 * expected / 6) << f;
}

std::string error_of(const hotgauge::core::Result<Model>& r) {
    EXPECT_FALSE(r) << "accepted a bad file";
    return r ? "" : r.error().message;
}

}  // namespace

// ---- model files ----

using ModelFile = TempDir;

TEST_F(ModelFile, RecipeModelRoundTripIsBitExact) {
    const Model m = recipe_model();
    ASSERT_TRUE(m.axisymmetric);
    ASSERT_FALSE(m.entries.empty());
    const fs::path p = path("hub-a.hgm");
    ASSERT_TRUE(write_model(m, p));
    EXPECT_FALSE(fs::exists(p.string() + ".tmp"));
    auto back = read_model(p);
    ASSERT_TRUE(back) << back.error().message;
    expect_same_model(m, *back);
    // Writing what was read gives the same bytes; overwriting an existing file works.
    const Bytes first = read_all(p);
    ASSERT_TRUE(write_model(*back, p));
    EXPECT_EQ(read_all(p), first);
    const Bytes magic = {'H', 'G', 'P', 'P', 'F', 0, '\r', '\n', 2, 0, 0, 0};
    EXPECT_TRUE(std::equal(magic.begin(), magic.end(), first.begin()));
}

TEST_F(ModelFile, SampleModelRoundTripIsBitExact) {
    write_text(path("cube.ply"), cube_ply_ascii_quads());
    auto s = read_mesh_samples(path("cube.ply"), 0.5);
    ASSERT_TRUE(s) << s.error().message;
    hotgauge::match::ModelConfig config;
    config.sampling_mm = 2.0;
    auto m =
        hotgauge::match::model_from_samples("cube", "mesh cube.ply", s->points, s->normals, config);
    ASSERT_TRUE(m) << m.error().message;
    ASSERT_FALSE(m->dense_points.empty());
    ASSERT_TRUE(write_model(*m, path("cube.hgm")));
    auto back = read_model(path("cube.hgm"));
    ASSERT_TRUE(back) << back.error().message;
    expect_same_model(*m, *back);
}

TEST_F(ModelFile, RefusesToWriteAnInvalidModel) {
    Model m = recipe_model();
    m.refs.push_back(static_cast<std::uint32_t>(m.points.size()));
    auto w = write_model(m, path("bad.hgm"));
    ASSERT_FALSE(w);
    EXPECT_NE(w.error().message.find("bad.hgm"), std::string::npos) << w.error().message;
    EXPECT_FALSE(fs::exists(path("bad.hgm")));
    EXPECT_FALSE(fs::exists(path("bad.hgm.tmp")));
}

TEST_F(ModelFile, EveryBadFileIsAClearError) {
    const Model m = recipe_model();
    const fs::path good = path("good.hgm");
    ASSERT_TRUE(write_model(m, good));
    const Bytes bytes = read_all(good);
    const fs::path p = path("bad.hgm");
    auto error_for = [&](const Bytes& b) {
        write_all(p, b);
        const std::string msg = error_of(read_model(p));
        EXPECT_EQ(msg.rfind(p.string() + ": ", 0), 0u) << "does not name the file: " << msg;
        return msg;
    };
    auto has = [](const std::string& msg, const char* what) {
        return msg.find(what) != std::string::npos;
    };

    EXPECT_TRUE(has(error_of(read_model(path("none.hgm"))), "none.hgm: missing"));
    EXPECT_TRUE(has(error_for({}), "empty file"));

    Bytes b = bytes;
    b[b.size() / 2] ^= 0x10;
    EXPECT_TRUE(has(error_for(b), "corrupt: checksum mismatch"));

    b = bytes;
    b[8] = 1;
    const std::string version = error_for(b);
    EXPECT_TRUE(has(version, "model format version 1, this build reads 2")) << version;
    EXPECT_TRUE(has(version, "hotgauge model build")) << version;

    // Text-mode transfer: "\r\n" in the magic became "\n".
    b = bytes;
    b.erase(b.begin() + 6);
    EXPECT_TRUE(has(error_for(b), "not a hotgauge model file"));

    for (std::size_t len :
         {std::size_t{1}, std::size_t{5}, std::size_t{8}, std::size_t{11}, std::size_t{12},
          std::size_t{19}, std::size_t{20}, std::size_t{21}, std::size_t{100}, bytes.size() / 3,
          bytes.size() - 9, bytes.size() - 8, bytes.size() - 1}) {
        const std::string msg = error_for(Bytes(bytes.begin(), bytes.begin() + len));
        EXPECT_TRUE(has(msg, "truncated")) << len << ": " << msg;
    }
    b = bytes;
    b.push_back(0);
    EXPECT_TRUE(has(error_for(b), "unexpected bytes after the checksum"));

    // A count far larger than the file, with a valid checksum: an error, not an allocation.
    b = bytes;
    put_le(b, 20, std::uint64_t{1} << 60, 8);  // length of the name
    reseal(b);
    const std::string count = error_for(b);
    EXPECT_TRUE(has(count, "name: count 1152921504606846976 needs more than")) << count;

    // A well-formed file of an invalid model (a reference beyond the samples): validate() says.
    b = bytes;
    put_le(b, refs_offset(m), 0xfffffff0u, 4);
    reseal(b);
    const std::string invalid = error_for(b);
    EXPECT_TRUE(has(invalid, "invalid model: model: a reference index is out of range")) << invalid;

    // Random garbage, with and without the magic in front.
    std::mt19937 rng(5);
    for (std::size_t len : {1u, 7u, 20u, 64u, 4096u}) {
        Bytes g(len);
        for (auto& c : g) c = static_cast<unsigned char>(rng());
        EXPECT_TRUE(has(error_for(g), "not a hotgauge model file")) << len;
        Bytes with_magic(bytes.begin(), bytes.begin() + 12);
        with_magic.insert(with_magic.end(), g.begin(), g.end());
        EXPECT_FALSE(error_for(with_magic).empty()) << len;
    }
}

// A model whose bytes are what a writer wrote (the checksum holds) but whose numbers are not
// finite made every part "not found" with exit 0 (issue 18, finding 7): refused when read.
TEST_F(ModelFile, NonFiniteNumbersBehindAGoodChecksumAreRefused) {
    const Model m = recipe_model();
    ASSERT_TRUE(write_model(m, path("good.hgm")));
    const Bytes bytes = read_all(path("good.hgm"));
    const auto replaced = [&](const void* what, const void* with, std::size_t n) {
        Bytes b = bytes;
        const auto* w = static_cast<const unsigned char*>(what);
        const auto at = std::search(b.begin(), b.end(), w, w + n);
        EXPECT_NE(at, b.end()) << "pattern not in the file";
        if (at != b.end()) std::memcpy(&*at, with, n);
        reseal(b);
        write_all(path("bad.hgm"), b);
        return error_of(read_model(path("bad.hgm")));
    };
    Eigen::Vector3f point = m.points[m.points.size() / 2];
    const Eigen::Vector3f original = point;
    point.y() = std::numeric_limits<float>::quiet_NaN();
    EXPECT_NE(replaced(original.data(), point.data(), sizeof point)
                  .find("invalid model: model: a sample point is not finite"),
              std::string::npos);
    ASSERT_FALSE(m.profile.empty());
    const auto& segment = m.profile.front();  // r0, z0, r1, z1: four doubles in the file
    const std::array<double, 4> stored = {segment.r0, segment.z0, segment.r1, segment.z1};
    const std::array<double, 4> infinite = {segment.r0, std::numeric_limits<double>::infinity(),
                                            segment.r1, segment.z1};
    const std::string e = replaced(stored.data(), infinite.data(), sizeof stored);
    EXPECT_NE(e.find("a profile segment is not finite"), std::string::npos) << e;
    // A negative radius, a point 100 m away, a segment of no length: refused alike.
    for (const std::array<double, 4>& bad :
         {std::array<double, 4>{-1.0, segment.z0, segment.r1, segment.z1},
          std::array<double, 4>{segment.r0, 1e5, segment.r1, segment.z1},
          std::array<double, 4>{segment.r0, segment.z0, segment.r0, segment.z0}}) {
        const std::string why = replaced(stored.data(), bad.data(), sizeof stored);
        EXPECT_NE(why.find("a profile segment is not finite, outside"), std::string::npos) << why;
    }
}

// Random edits of the body behind a recomputed checksum: whatever the reader makes of them, it
// returns (a model that passes validate(), or an error naming the file) and never crashes.
TEST_F(ModelFile, ResealedRandomEditsNeverCrash) {
    const Model m = recipe_model(15.0);  // a small file: many trials in little time
    ASSERT_TRUE(write_model(m, path("good.hgm")));
    const Bytes bytes = read_all(path("good.hgm"));
    const fs::path p = path("edit.hgm");
    std::mt19937 rng(11);
    int rejected = 0;
    for (int trial = 0; trial < 120; ++trial) {
        Bytes b = bytes;
        // Mostly in the first kilobyte, where the counts are.
        const std::size_t span = trial % 2 ? 1024 : b.size() - 28;
        for (int k = 0; k < 1 + trial % 3; ++k)
            b[20 + rng() % span] = static_cast<unsigned char>(rng());
        reseal(b);
        write_all(p, b);
        auto r = read_model(p);
        if (r) {
            EXPECT_TRUE(r->validate());
        } else {
            ++rejected;
            EXPECT_EQ(r.error().message.rfind(p.string() + ": ", 0), 0u) << r.error().message;
        }
    }
    EXPECT_GT(rejected, 0);
}

// ---- meshes ----

using MeshFile = TempDir;

TEST_F(MeshFile, CubeInEveryFormat) {
    write_text(path("ascii_quads.ply"), cube_ply_ascii_quads());
    write_all(path("binary.ply"), cube_ply_binary());
    write_text(path("ascii.stl"), cube_stl_ascii());
    write_all(path("binary.stl"), cube_stl_binary());
    for (const char* name : {"ascii_quads.ply", "binary.ply", "ascii.stl", "binary.stl"}) {
        SCOPED_TRACE(name);
        for (double spacing : {0.5, 1.0}) {
            auto s = read_mesh_samples(path(name), spacing);
            ASSERT_TRUE(s) << s.error().message;
            expect_cube_samples(*s, spacing);
        }
    }
    // Fixed seed: the same file gives the same samples.
    auto a = read_mesh_samples(path("binary.stl"), 0.5),
         b = read_mesh_samples(path("binary.stl"), 0.5);
    ASSERT_TRUE(a && b);
    EXPECT_EQ(a->points, b->points);
}

TEST_F(MeshFile, DegenerateTrianglesAreSkipped) {
    std::string ply = cube_ply_ascii_quads();
    // Two more faces: a repeated vertex and three collinear vertices (0, 1 and 0 again).
    ply.replace(ply.find("element face 6"), 14, "element face 8");
    ply += "3 0 0 5\n3 0 1 0\n";
    write_text(path("cube.ply"), ply);
    auto s = read_mesh_samples(path("cube.ply"), 0.5);
    ASSERT_TRUE(s) << s.error().message;
    expect_cube_samples(*s, 0.5);
}

// A big-endian PLY that VTK wrote (PCL's PLYWriter writes the host's byte order only), read into
// the same cube samples, and made into a model as `hotgauge model build --mesh` does.
TEST_F(MeshFile, BigEndianPlyWrittenByVtk) {
    vtkNew<vtkPoints> points;  // float: "property float x"
    for (const auto& v : cube_vertices()) points->InsertNextPoint(v.x(), v.y(), v.z());
    vtkNew<vtkCellArray> quads;
    for (const auto& q : kCubeQuads) {
        const vtkIdType ids[4] = {q[0], q[1], q[2], q[3]};
        quads->InsertNextCell(4, ids);
    }
    vtkNew<vtkPolyData> cube;
    cube->SetPoints(points);
    cube->SetPolys(quads);
    vtkNew<vtkPLYWriter> writer;
    writer->SetInputData(cube);
    writer->SetFileName(path("be.ply").c_str());
    writer->SetFileTypeToBinary();
    writer->SetDataByteOrderToBigEndian();
    ASSERT_EQ(writer->Write(), 1);
    const Bytes file = read_all(path("be.ply"));
    const std::string format = "format binary_big_endian 1.0";
    ASSERT_NE(std::search(file.begin(), file.end(), format.begin(), format.end()), file.end());

    auto s = read_mesh_samples(path("be.ply"), 0.5);
    ASSERT_TRUE(s) << s.error().message;
    expect_cube_samples(*s, 0.5);
    hotgauge::match::ModelConfig config;
    config.sampling_mm = 2.0;
    auto m =
        hotgauge::match::model_from_samples("cube", "mesh be.ply", s->points, s->normals, config);
    ASSERT_TRUE(m) << m.error().message;
    EXPECT_FALSE(m->dense_points.empty());
    const std::string cli = model_build("--mesh", path("be.ply"));
    EXPECT_TRUE(cli == "no HOTGAUGE_CLI" ||
                cli.find("(mesh " + path("be.ply").string() + ")") != std::string::npos)
        << cli;
}

TEST_F(MeshFile, Errors) {
    auto error = [&](const std::string& name, const Bytes& content) {
        write_all(path(name), content);
        auto s = read_mesh_samples(path(name), 0.5);
        EXPECT_FALSE(s) << name << " accepted";
        const std::string msg = s ? "" : s.error().message;
        EXPECT_EQ(msg.rfind(path(name).string() + ": ", 0), 0u) << msg;
        return msg;
    };
    auto text = [](const std::string& t) { return Bytes(t.begin(), t.end()); };
    auto has = [](const std::string& msg, const char* what) {
        return msg.find(what) != std::string::npos;
    };
    auto replaced = [](std::string t, const std::string& from, const std::string& to) {
        t.replace(t.find(from), from.size(), to);
        return t;
    };
    const std::string ply = cube_ply_ascii_quads();

    auto missing = read_mesh_samples(path("none.stl"), 0.5);
    ASSERT_FALSE(missing);
    EXPECT_TRUE(has(missing.error().message, "none.stl: no such file"));
    EXPECT_TRUE(has(error("cube.obj", text(ply)), "expected a mesh file .ply or .stl"));
    // PCL's PLYReader fails with -1 and no reason we can get: the message says what it can be.
    constexpr const char* kNotPly = "PCL cannot read it as PLY (not a PLY file, a bad header, or";
    EXPECT_TRUE(has(error("empty.ply", {}), kNotPly));
    EXPECT_TRUE(has(error("notply.ply", text("solid x\n" + ply)), kNotPly));
    EXPECT_TRUE(has(error("noend.ply", text(replaced(ply, "end_header", "end_heade"))), kNotPly));
    EXPECT_TRUE(has(error("range.ply", text(replaced(ply, "4 1 3 7 5", "4 1 3 8 5"))),
                    "face 5: vertex index 8 out of range (8 vertices)"));
    EXPECT_TRUE(
        has(error("neg.ply", text(replaced(ply, "4 1 3 7 5", "4 1 3 -1 5"))), "out of range"));
    // PCL reads a word that is not a number as NaN (as 0 in an integer list: not detectable).
    EXPECT_TRUE(has(error("nan.ply", text(replaced(ply, "end_header\n1 ", "end_header\nx "))),
                    "face 0: vertex 0 is not finite"));
    EXPECT_TRUE(has(error("short.ply", text(ply.substr(0, ply.size() - 12))), "truncated"));
    EXPECT_TRUE(has(error("noface.ply", text(replaced(ply, "element face 6", "element face 0"))),
                    "no triangles"));
    EXPECT_TRUE(
        has(error("flat.ply", text(replaced(replaced(ply, "element face 6", "element face 1"),
                                            "4 0 2 3 1", "3 0 1 0"))),
            "no triangles with an area"));
    const Bytes bin = cube_ply_binary();
    for (std::size_t cut : {std::size_t{1}, std::size_t{13}, std::size_t{100}})
        EXPECT_TRUE(has(error("cut.ply", Bytes(bin.begin(), bin.end() - cut)), "truncated"));
    Bytes huge_list = bin;  // the first face's count becomes 2^31 - 1
    const std::size_t first_face = bin.size() - 12 * 20;
    put_le(huge_list, first_face, 0x7fffffff, 4);
    EXPECT_TRUE(has(error("list.ply", huge_list), "truncated"));

    // ascii STL: vtkSTLReader's own messages, after the line number.
    const std::string stl = cube_stl_ascii();
    const std::string noend = error("noend.stl", text(stl.substr(0, stl.find("endsolid"))));
    EXPECT_TRUE(has(noend, "VTK cannot read it as STL: at line ")) << noend;
    EXPECT_TRUE(has(noend, "Premature EOF while reading 'facet'")) << noend;
    EXPECT_TRUE(has(error("typo.stl", text(replaced(stl, "outer loop", "outr loop"))),
                    "Expecting 'outer loop' found 'outr'"));
    EXPECT_TRUE(has(error("coord.stl", text(replaced(stl, "vertex 1", "vertex one"))),
                    "Parse error reading STL vertex"));
    EXPECT_TRUE(has(error("empty.stl", text("solid nothing\nendsolid nothing\n")), "no triangles"));
    const Bytes bstl = cube_stl_binary();
    Bytes cut_stl(bstl.begin(), bstl.end() - 50);
    cut_stl[0] = 'x';  // not "solid": only binary is possible
    EXPECT_TRUE(has(error("cut.stl", cut_stl), "truncated: binary STL of 12 triangles"));
    EXPECT_TRUE(has(error("tiny.stl", text("abc")), "Expecting 'solid' found 'abc'"));
    auto bad_spacing = read_mesh_samples(path("noend.stl"), 0.0);
    ASSERT_FALSE(bad_spacing);
    EXPECT_TRUE(has(bad_spacing.error().message, "spacing"));
}

// ---- scans ----

using ScanFile = TempDir;

namespace {

// A 30 × 30 grid with 1 mm pitch on the plane z = z0 + slope·x, small deterministic jitter in
// x and y so that the grid is not perfectly regular.
std::vector<Eigen::Vector3f> plane_points(double slope) {
    std::vector<Eigen::Vector3f> pts;
    std::mt19937 rng(3);
    for (int i = 0; i < 30; ++i)
        for (int j = 0; j < 30; ++j) {
            const double x = i + 0.1 * (static_cast<double>(rng() % 1000) / 1000 - 0.5);
            const double y = j + 0.1 * (static_cast<double>(rng() % 1000) / 1000 - 0.5);
            pts.emplace_back(static_cast<float>(x), static_cast<float>(y),
                             static_cast<float>(5.0 + slope * x));
        }
    return pts;
}

std::string pcd_header(const std::string& fields, const std::string& size, const std::string& type,
                       const std::string& count, std::size_t n, const std::string& data) {
    std::ostringstream s;
    s << "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS " << fields << "\nSIZE "
      << size << "\nTYPE " << type << "\nCOUNT " << count << "\nWIDTH " << n
      << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << n << "\nDATA " << data << "\n";
    return s.str();
}

void expect_normals(const SurfaceSamples& s, const Eigen::Vector3f& expected, std::size_t n) {
    ASSERT_EQ(s.points.size(), n);
    ASSERT_EQ(s.normals.size(), n);
    for (std::size_t i = 0; i < n; ++i)
        ASSERT_LT((s.normals[i] - expected).norm(), 1e-4) << i << ": " << s.normals[i].transpose();
}

}  // namespace

TEST_F(ScanFile, PlaneWithoutNormalsGetsUpwardPcaNormals) {
    const auto flat = plane_points(0.0);
    const std::size_t n = flat.size();
    // ascii PCD with an extra field, binary PCD with an rgb field between, binary PLY.
    std::ostringstream ascii;
    ascii << pcd_header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", n + 1, "ascii");
    for (const auto& p : flat) ascii << p.x() << ' ' << p.y() << ' ' << p.z() << " 7\n";
    ascii << "nan nan nan 0\n";  // an invalid point, as organised clouds have: dropped
    write_text(path("ascii.pcd"), ascii.str());

    const std::string h = pcd_header("x rgb y z", "4 4 8 4", "F U F F", "1 1 1 1", n, "binary");
    Bytes bin(h.begin(), h.end());
    for (const auto& p : flat) {
        append(bin, p.x());
        append(bin, std::uint32_t{0xff0000});
        append(bin, static_cast<double>(p.y()));
        append(bin, p.z());
    }
    write_all(path("binary.pcd"), bin);

    const std::string ph = "ply\nformat binary_little_endian 1.0\nelement vertex " +
                           std::to_string(n) +
                           "\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    Bytes ply(ph.begin(), ph.end());
    for (const auto& p : flat) {
        append(ply, p.x());
        append(ply, p.y());
        append(ply, p.z());
    }
    write_all(path("scan.ply"), ply);

    for (const char* name : {"ascii.pcd", "binary.pcd", "scan.ply"}) {
        SCOPED_TRACE(name);
        auto s = read_scan_samples(path(name));
        ASSERT_TRUE(s) << s.error().message;
        expect_normals(*s, Eigen::Vector3f::UnitZ(), n);
        EXPECT_EQ(s->points[0], flat[0]);
    }
}

TEST_F(ScanFile, TiltedPlaneNormalsAndNormalsFromTheFile) {
    // A plane falling towards +x: PCA gives (0.5, 0, 1)/|…|, oriented towards +z.
    const auto tilted = plane_points(-0.5);
    std::ostringstream ascii;
    ascii << pcd_header("x y z", "4 4 4", "F F F", "1 1 1", tilted.size(), "ascii");
    for (const auto& p : tilted) ascii << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
    write_text(path("tilted.pcd"), ascii.str());
    auto s = read_scan_samples(path("tilted.pcd"));
    ASSERT_TRUE(s) << s.error().message;
    expect_normals(*s, Eigen::Vector3f(0.5f, 0, 1).normalized(), tilted.size());

    // Normals in the file are used as they are (normalised), even pointing down.
    std::ostringstream with;
    with << pcd_header("x y z normal_x normal_y normal_z curvature", "4 4 4 4 4 4 4",
                       "F F F F F F F", "1 1 1 1 1 1 1", tilted.size(), "ascii");
    for (const auto& p : tilted) with << p.x() << ' ' << p.y() << ' ' << p.z() << " 0 0 -2 0\n";
    write_text(path("normals.pcd"), with.str());
    s = read_scan_samples(path("normals.pcd"));
    ASSERT_TRUE(s) << s.error().message;
    expect_normals(*s, -Eigen::Vector3f::UnitZ(), tilted.size());

    std::ostringstream ply;
    ply << "ply\nformat ascii 1.0\nelement vertex " << tilted.size()
        << "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\n"
           "property float ny\nproperty float nz\nend_header\n";
    for (const auto& p : tilted) ply << p.x() << ' ' << p.y() << ' ' << p.z() << " 1 0 0\n";
    write_text(path("normals.ply"), ply.str());
    s = read_scan_samples(path("normals.ply"));
    ASSERT_TRUE(s) << s.error().message;
    expect_normals(*s, Eigen::Vector3f::UnitX(), tilted.size());
}

TEST_F(ScanFile, Errors) {
    auto error = [&](const std::string& name, const std::string& content) {
        write_text(path(name), content);
        auto s = read_scan_samples(path(name));
        EXPECT_FALSE(s) << name << " accepted";
        const std::string msg = s ? "" : s.error().message;
        EXPECT_EQ(msg.rfind(path(name).string() + ": ", 0), 0u) << msg;
        return msg;
    };
    auto has = [](const std::string& msg, const char* what) {
        return msg.find(what) != std::string::npos;
    };
    const std::string xyz = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 100, "binary");
    EXPECT_TRUE(has(error("scan.xyz", xyz), "expected a scan file .ply or .pcd"));
    EXPECT_TRUE(has(error("cut.pcd", xyz + std::string(100 * 12 - 1, '\0')), "truncated"));
    EXPECT_TRUE(has(
        error("cut2.pcd", pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 100, "ascii") + "1 2 3\n"),
        "truncated"));
    // binary_compressed is read (CompressedPcdAndBigEndianPlyWrittenByPclAndVtk), a header
    // without its data is not.
    EXPECT_TRUE(has(
        error("zip.pcd", pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 100, "binary_compressed")),
        "PCD binary_compressed data of 100 points: truncated or corrupt"));
    EXPECT_TRUE(has(error("noz.pcd", pcd_header("x y w", "4 4 4", "F F F", "1 1 1", 0, "ascii")),
                    "no x, y, z fields"));
    EXPECT_TRUE(has(error("half.pcd", pcd_header("x y z normal_x", "4 4 4 4", "F F F F", "1 1 1 1",
                                                 0, "ascii")),
                    "some of normal_x"));
    EXPECT_TRUE(has(error("type.pcd", pcd_header("x y z", "4 4 3", "F F F", "1 1 1", 0, "ascii")),
                    "field 'z' has a type or size PCL does not read"));
    // PCL's header reader skips lines it does not know and needs no DATA line: such files come
    // back as clouds without fields or points, refused for that.
    EXPECT_TRUE(has(error("nodata.pcd", "VERSION 0.7\nFIELDS x y z\n"), "0 valid points of 0"));
    EXPECT_TRUE(has(error("garbage.pcd", "\x01\x02 hello\n"), "PCD has no x, y, z fields"));
    EXPECT_TRUE(has(error("two.pcd", pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 2, "ascii") +
                                         "0 0 0\n1 1 1\n"),
                    "2 valid points of 2"));
    EXPECT_TRUE(has(error(
                        "line.pcd", pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 20, "ascii") +
                                        [] {
                                            std::string s;
                                            for (int i = 0; i < 20; ++i)
                                                s += std::to_string(i) + " 0 0\n";
                                            return s;
                                        }()),
                    "on a line"));
    EXPECT_TRUE(has(error("nov.ply", "ply\nformat ascii 1.0\nelement face 0\nend_header\n"),
                    "PLY has no x, y, z fields"));
}

namespace {

// The plane as PCL's binary_compressed PCD (LZF): x y z floats, and normal_x normal_y normal_z
// (0, 0, −1) when `with_normals`.
void write_compressed_pcd(const fs::path& p, const std::vector<Eigen::Vector3f>& points,
                          bool with_normals) {
    pcl::PCLPointCloud2 cloud;
    std::vector<std::string> names = {"x", "y", "z"};
    if (with_normals) names.insert(names.end(), {"normal_x", "normal_y", "normal_z"});
    for (std::size_t i = 0; i < names.size(); ++i) {
        pcl::PCLPointField f;
        f.name = names[i];
        f.offset = static_cast<std::uint32_t>(4 * i);
        f.datatype = pcl::PCLPointField::FLOAT32;
        f.count = 1;
        cloud.fields.push_back(f);
    }
    cloud.point_step = static_cast<std::uint32_t>(4 * names.size());
    cloud.width = static_cast<std::uint32_t>(points.size());
    cloud.height = 1;
    cloud.row_step = cloud.point_step * cloud.width;
    cloud.is_dense = true;
    for (const auto& pt : points) {
        std::vector<float> v = {pt.x(), pt.y(), pt.z()};
        if (with_normals) v.insert(v.end(), {0.0f, 0.0f, -1.0f});
        const auto* bytes = reinterpret_cast<const std::uint8_t*>(v.data());
        cloud.data.insert(cloud.data.end(), bytes, bytes + 4 * v.size());
    }
    ASSERT_EQ(pcl::PCDWriter().writeBinaryCompressed(p.string(), cloud), 0);
    const Bytes file = read_all(p);
    const std::string data = "DATA binary_compressed";
    ASSERT_NE(std::search(file.begin(), file.end(), data.begin(), data.end()), file.end());
}

}  // namespace

// binary_compressed PCD that PCL wrote, as `hotgauge model build --scan` reads it: PCA normals
// without normals in the file, the file's normals with them; and the same plane as a big-endian
// PLY (double coordinates) that VTK wrote.
TEST_F(ScanFile, CompressedPcdAndBigEndianPlyWrittenByPclAndVtk) {
    const auto flat = plane_points(0.0);
    write_compressed_pcd(path("plane.pcd"), flat, false);
    write_compressed_pcd(path("normals.pcd"), flat, true);

    vtkNew<vtkPoints> points;
    points->SetDataTypeToDouble();
    for (const auto& p : flat) points->InsertNextPoint(p.x(), p.y(), p.z());
    vtkNew<vtkPolyData> cloud;
    cloud->SetPoints(points);
    vtkNew<vtkPLYWriter> writer;
    writer->SetInputData(cloud);
    writer->SetFileName(path("be.ply").c_str());
    writer->SetFileTypeToBinary();
    writer->SetDataByteOrderToBigEndian();
    ASSERT_EQ(writer->Write(), 1);

    for (const char* name : {"plane.pcd", "be.ply"}) {
        SCOPED_TRACE(name);
        auto s = read_scan_samples(path(name));
        ASSERT_TRUE(s) << s.error().message;
        expect_normals(*s, Eigen::Vector3f::UnitZ(), flat.size());
        EXPECT_EQ(s->points, flat);
        auto m = hotgauge::match::model_from_samples("plane", std::string("scan ") + name,
                                                     s->points, s->normals, {});
        ASSERT_TRUE(m) << m.error().message;
    }
    auto s = read_scan_samples(path("normals.pcd"));
    ASSERT_TRUE(s) << s.error().message;
    expect_normals(*s, -Eigen::Vector3f::UnitZ(), flat.size());
    for (const char* name : {"plane.pcd", "normals.pcd", "be.ply"}) {
        const std::string cli = model_build("--scan", path(name));
        EXPECT_TRUE(cli == "no HOTGAUGE_CLI" ||
                    cli.find("(scan " + path(name).string() + ")") != std::string::npos)
            << cli;
    }
}
