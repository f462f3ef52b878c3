// hotgauge_oracle_render: an independent oracle for the measurement. Renders the reference part
// (a recipe of kind "axisymmetric", e.g. hub-a) as an exact triangle mesh with Embree 3 into a
// recording of format hotgauge-recording/1, and writes the truth beside it.
//
// Written from the recording format document (recording-format-v1.md), the part document
// (hub-a.md) and the recipe: the ray casting (Embree), the sensor model and the writers are its
// own. The ideal part (sharp corners, vertical walls, one axis) comes from its own reading of the
// recipe. `--forged` renders the part as it leaves the press (hub-a.md "As forged"): its drawing
// rules are ours (core::build_forged, the shape drawn as docs/simulator.md "As-forged parts"
// says), so that the truth's sharp-corner features mean what the simulator's mean; what stays
// independent is how the surface is turned into points.
//
//   hotgauge_oracle_render --recipe hub-a.yaml --out DIR [--geometry ours|downDEG]
//       [--temperature C] [--x MM] [--y MM] [--yaw-deg D] [--phase F] [--noise SIGMA_MM]
//       [--dropout P] [--seed S] [--part-id ID] [--threads N] [--segments N]
//       [--forged [--dimension-sigma MM] [--bad "NAME=DELTA"]...]
//
// Output: DIR/part/ (the recording), DIR/part_pose.yaml (world_from_part), DIR/truth.json.
#include <embree3/rtcore.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "hotgauge/core/forged.hpp"
#include "hotgauge/io/recipe.hpp"

namespace {

static_assert(std::endian::native == std::endian::little, "the .npy writer assumes little-endian");

using Eigen::Matrix3d;
using Eigen::Matrix4d;
using Eigen::Vector3d;

constexpr double kPi = 3.14159265358979323846;
constexpr int kWidth = 2048;          // rays per profile
constexpr double kPitch = 0.2;        // mm, point pitch at the standoff and profile spacing
constexpr double kStandoff = 890.0;   // mm
constexpr double kMinRange = 600.0;   // mm, camera z
constexpr double kMaxRange = 1200.0;  // mm, camera z
constexpr double kMaxIncidenceDeg = 85.0;
constexpr double kScanMargin = 15.0;                // mm beyond the hot radius, either side
constexpr std::int64_t kLinePeriodNs = 1000000;     // 1 kHz
constexpr std::int64_t kAccelPeriodNs = 500000;     // 2 kHz
constexpr std::int64_t kAccelMarginNs = 600000000;  // 0.6 s
constexpr std::int64_t kFaceGapNs = 2000000000;     // 2 s
constexpr std::int64_t kStartNs = 1790000000000000000;
constexpr double kGravity = 9.81;
constexpr double kPlateHalf = 200.0;  // mm, 400 x 400 support plate, top at z = 0
constexpr int kPacket = 16;           // rays per rtcIntersect16
static_assert(kWidth % kPacket == 0);
constexpr unsigned kMaskPart = 1u;
constexpr unsigned kMaskPlate = 2u;

// ---------------------------------------------------------------------------------------------
// Options

struct Options {
    std::string recipe;
    std::string out;
    std::string geometry = "ours";
    std::string part_id = "ORACLE-1";
    double temperature = 1050.0;
    double x = 0.0;
    double y = 0.0;
    double yaw_deg = 0.0;
    double phase = 0.0;
    double noise = 0.0;
    double dropout = 0.0;
    std::uint64_t seed = 1;
    int threads = 0;
    int segments = 4096;
    // As forged: drafts, fillets, die shift and dimensions drawn from the seed (draw_forged).
    bool forged = false;
    double dimension_sigma = 0.05;                    // mm, N(0, σ) on every level and diameter
    std::vector<std::pair<std::string, double>> bad;  // feature name -> mm added to its value
};

[[noreturn]] void usage(const std::string& why) {
    std::cerr << "hotgauge_oracle_render: " << why << "\n"
              << "usage: hotgauge_oracle_render --recipe FILE --out DIR [--geometry ours|downDEG]\n"
                 "  [--temperature C] [--x MM] [--y MM] [--yaw-deg D] [--phase F]\n"
                 "  [--noise SIGMA_MM] [--dropout P] [--seed S] [--part-id ID] [--threads N]\n"
                 "  [--segments N] [--forged [--dimension-sigma MM] [--bad \"NAME=DELTA\"]...]\n";
    std::exit(2);
}

double to_double(const std::string& key, const std::string& v) {
    try {
        std::size_t used = 0;
        const double d = std::stod(v, &used);
        if (used != v.size() || !std::isfinite(d)) throw std::invalid_argument(v);
        return d;
    } catch (const std::exception&) {
        usage(key + ": not a number: " + v);
    }
}

Options parse(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string key = argv[i];
        if (key == "-h" || key == "--help") usage("help");
        if (key == "--forged") {
            o.forged = true;
            continue;
        }
        if (i + 1 >= argc) usage(key + " needs a value");
        const std::string v = argv[++i];
        if (key == "--recipe") {
            o.recipe = v;
        } else if (key == "--out") {
            o.out = v;
        } else if (key == "--geometry") {
            o.geometry = v;
        } else if (key == "--part-id") {
            o.part_id = v;
        } else if (key == "--temperature") {
            o.temperature = to_double(key, v);
        } else if (key == "--x") {
            o.x = to_double(key, v);
        } else if (key == "--y") {
            o.y = to_double(key, v);
        } else if (key == "--yaw-deg") {
            o.yaw_deg = to_double(key, v);
        } else if (key == "--phase") {
            o.phase = to_double(key, v);
        } else if (key == "--noise") {
            o.noise = to_double(key, v);
        } else if (key == "--dropout") {
            o.dropout = to_double(key, v);
        } else if (key == "--seed") {
            try {
                o.seed = std::stoull(v);
            } catch (const std::exception&) {
                usage("--seed: not an unsigned integer: " + v);
            }
        } else if (key == "--threads") {
            o.threads = static_cast<int>(to_double(key, v));
        } else if (key == "--segments") {
            o.segments = static_cast<int>(to_double(key, v));
        } else if (key == "--dimension-sigma") {
            o.dimension_sigma = to_double(key, v);
        } else if (key == "--bad") {
            const auto eq = v.rfind('=');
            if (eq == std::string::npos || eq == 0) usage("--bad: expected NAME=DELTA, got " + v);
            o.bad.emplace_back(v.substr(0, eq), to_double(key, v.substr(eq + 1)));
        } else {
            usage("unknown option " + key);
        }
    }
    if (o.recipe.empty() || o.out.empty()) usage("--recipe and --out are required");
    if (o.geometry != "ours" &&
        !(o.geometry.rfind("down", 0) == 0 && o.geometry.size() > 4 &&
          o.geometry.find_first_not_of("0123456789", 4) == std::string::npos &&
          std::stoi(o.geometry.substr(4)) <= 45))
        usage("--geometry: ours or downDEG (side sensors DEG° down, at most 45)");
    if (!(o.phase >= 0.0 && o.phase < 1.0)) usage("--phase must be in [0, 1)");
    if (o.noise < 0.0 || o.dropout < 0.0 || o.dropout >= 1.0) usage("bad --noise / --dropout");
    if (o.segments < 16) usage("--segments must be >= 16");
    if (!o.forged && (!o.bad.empty() || o.dimension_sigma != 0.05))
        usage("--bad and --dimension-sigma need --forged");
    if (o.dimension_sigma < 0.0) usage("--dimension-sigma must be >= 0");
    if (o.threads <= 0)
        o.threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    return o;
}

// ---------------------------------------------------------------------------------------------
// Recipe (cold, part frame, mm)

struct Section {
    std::string name;
    std::string from;
    std::string to;
    double diameter = 0.0;
};

struct Feature {
    std::string name;
    std::string kind;  // diameter | height
    std::vector<std::string> faces;
    std::string section;  // diameters
    std::string from;     // heights
    std::string to;
    double nominal = 0.0;
};

struct Recipe {
    std::string name;
    std::vector<std::pair<std::string, double>> levels;  // recipe order
    std::vector<Section> outer;
    std::vector<Section> inner;
    double alpha0 = 0.0;
    double alpha1 = 0.0;
    std::vector<Feature> features;

    double level(const std::string& n) const {
        for (const auto& [k, z] : levels)
            if (k == n) return z;
        throw std::runtime_error("recipe: unknown level '" + n + "'");
    }
    const Section& section(const std::string& n) const {
        for (const auto* list : {&outer, &inner})
            for (const auto& s : *list)
                if (s.name == n) return s;
        throw std::runtime_error("recipe: unknown section '" + n + "'");
    }
};

std::vector<Section> read_sections(const YAML::Node& node) {
    std::vector<Section> out;
    for (const auto& s : node)
        out.push_back({s["name"].as<std::string>(), s["from"].as<std::string>(),
                       s["to"].as<std::string>(), s["diameter_mm"].as<double>()});
    return out;
}

Recipe read_recipe(const std::string& path) {
    const YAML::Node doc = YAML::LoadFile(path);
    Recipe r;
    r.name = doc["part"].as<std::string>();
    const YAML::Node g = doc["geometry"];
    if (g["kind"].as<std::string>() != "axisymmetric")
        throw std::runtime_error(path + ": geometry.kind must be axisymmetric");
    for (const auto& kv : g["levels_mm"])
        r.levels.emplace_back(kv.first.as<std::string>(), kv.second.as<double>());
    r.outer = read_sections(g["outer"]);
    r.inner = read_sections(g["inner"]);
    r.alpha0 = doc["material"]["alpha0_per_k"].as<double>();
    r.alpha1 = doc["material"]["alpha1_per_k2"].as<double>();
    for (const auto& f : doc["features"]) {
        Feature ft;
        ft.name = f["name"].as<std::string>();
        ft.kind = f["kind"].as<std::string>();
        ft.faces = f["faces"].as<std::vector<std::string>>();
        if (ft.kind == "diameter") {
            ft.section = f["section"].as<std::string>();
        } else if (ft.kind == "height") {
            ft.from = f["from"].as<std::string>();
            ft.to = f["to"].as<std::string>();
        }
        ft.nominal = f["nominal_mm"].as<double>();
        r.features.push_back(ft);
    }
    if (r.outer.empty() || r.inner.empty()) throw std::runtime_error(path + ": no sections");
    return r;
}

// The closed (r, z) outline of the solid: up the outer sections, across the top, down the inner
// sections, across the bottom. Consecutive duplicates removed.
std::vector<Eigen::Vector2d> outline(const Recipe& rc) {
    auto check_chain = [&](const std::vector<Section>& list, const char* what) {
        for (std::size_t i = 0; i + 1 < list.size(); ++i)
            if (list[i].to != list[i + 1].from)
                throw std::runtime_error(std::string("recipe: ") + what +
                                         " sections are not contiguous");
    };
    check_chain(rc.outer, "outer");
    check_chain(rc.inner, "inner");
    if (rc.outer.front().from != rc.inner.front().from || rc.outer.back().to != rc.inner.back().to)
        throw std::runtime_error("recipe: outer and inner contours do not share their end levels");
    std::vector<Eigen::Vector2d> pts;
    auto push = [&](double r, double z) {
        const Eigen::Vector2d p(r, z);
        if (pts.empty() || (pts.back() - p).norm() > 1e-12) pts.push_back(p);
    };
    for (const auto& s : rc.outer) {
        push(s.diameter / 2, rc.level(s.from));
        push(s.diameter / 2, rc.level(s.to));
    }
    for (auto it = rc.inner.rbegin(); it != rc.inner.rend(); ++it) {
        push(it->diameter / 2, rc.level(it->to));
        push(it->diameter / 2, rc.level(it->from));
    }
    if ((pts.back() - pts.front()).norm() < 1e-12) pts.pop_back();
    for (const auto& p : pts)
        if (!(p.x() > 0)) throw std::runtime_error("recipe: outline touches the axis");
    return pts;
}

// ---------------------------------------------------------------------------------------------
// As forged (--forged): the shape drawn as docs/simulator.md "As-forged parts" says, from the
// oracle's own stream (the seed salted); core::build_forged makes its (r, z) profiles and the
// features at the theoretical sharp corners.

namespace core = hotgauge::core;

struct Forged {
    core::Recipe recipe;
    core::ForgedPart part;
    std::map<std::string, double> bad_mm;
    std::string die_shift_name;  // the recipe's die_shift feature, or "Die shift"
};

core::ForgedPart build(const core::Recipe& rc, const core::ForgedShape& shape) {
    auto part = core::build_forged(rc, shape);
    if (!part) throw std::runtime_error(part.error().message);
    return std::move(*part);
}

// Dimensions N(0, σ) (the origin level stays), the bad features, per wall a draft in [1°, the
// drawing's] (drawn again until the flat faces are kept), per corner a fillet in [1 mm, the
// drawing's], the die shift uniform in [0, 0.8 × the drawing's] at a random azimuth.
Forged draw_forged(const Options& o, double scale) {
    auto recipe = hotgauge::io::read_recipe(o.recipe);
    if (!recipe) throw std::runtime_error(recipe.error().message);
    Forged f{std::move(*recipe), {}, {}, "Die shift"};
    const core::Recipe& rc = f.recipe;
    if (!rc.forging) throw std::runtime_error(o.recipe + ": --forged needs a 'forging' drawing");
    for (const auto& ft : rc.features)
        if (ft.kind == core::FeatureKind::kDieShift) f.die_shift_name = ft.name;
    std::seed_seq seq{static_cast<std::uint32_t>(o.seed), static_cast<std::uint32_t>(o.seed >> 32),
                      0x666f7267u};
    std::mt19937_64 rng(seq);
    std::normal_distribution<double> gauss(0.0, 1.0);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    core::ForgedShape shape;
    shape.scale = scale;
    for (const auto& [name, z] : rc.levels_mm)
        shape.levels_mm[name] = z == 0.0 ? 0.0 : z + o.dimension_sigma * gauss(rng);
    for (const auto* list : {&rc.outer, &rc.inner})
        for (const auto& s : *list)
            shape.diameters_mm[s.name] = s.diameter_mm + o.dimension_sigma * gauss(rng);
    double shift_bad = 0.0;
    for (const auto& [name, delta] : o.bad) {
        f.bad_mm[name] += delta;
        if (name == f.die_shift_name) {
            shift_bad += delta;
            continue;
        }
        const auto ft = std::find_if(rc.features.begin(), rc.features.end(),
                                     [&](const core::FeatureSpec& s) { return s.name == name; });
        if (ft == rc.features.end()) throw std::runtime_error("--bad: no feature '" + name + "'");
        if (ft->kind == core::FeatureKind::kDiameter) {
            shape.diameters_mm.at(ft->section) += delta;
        } else {  // a height: its upper level moves
            const bool to_upper =
                rc.level(ft->to_level).value_or(0) >= rc.level(ft->from_level).value_or(0);
            shape.levels_mm.at(to_upper ? ft->to_level : ft->from_level) += delta;
        }
    }
    const core::ForgedPart undrafted = build(rc, shape);
    for (int attempt = 0;; ++attempt) {
        if (attempt == 1000) throw std::runtime_error("no drafts keep the flat faces");
        for (const auto& w : core::forged_walls(rc))
            shape.draft_deg[w.name] = core::draw_within(rc.draft_of(w.section), rng);
        if (core::flat_faces_kept(undrafted, build(rc, shape))) break;
    }
    for (const auto& c : core::forged_corners(rc))
        shape.fillet_mm[c.name] = core::draw_within(rc.fillet_at(c.level), rng);
    const double shift = std::max(0.0, 0.8 * rc.forging->die_shift_mm * u01(rng) + shift_bad);
    const double azimuth = 2.0 * kPi * u01(rng);
    shape.die_shift_mm = shift * Eigen::Vector2d(std::cos(azimuth), std::sin(azimuth));
    f.part = build(rc, shape);
    return f;
}

// ---------------------------------------------------------------------------------------------
// Scene: the hot part (revolved outline, world coordinates) and the support plate.

struct Mesh {
    std::vector<Vector3d> vertices;  // world, double
    std::vector<std::array<unsigned, 3>> triangles;
};

// The surface of revolution of the closed (r, z) outline `ol` (counter-clockwise: material on
// the left) about the axis through (axis_mm.x, axis_mm.y) of the part frame (hot mm).
Mesh part_mesh(const std::vector<Eigen::Vector2d>& ol, int segments, double scale,
               const Matrix4d& world_from_part,
               const Eigen::Vector2d& axis_mm = Eigen::Vector2d::Zero()) {
    double area2 = 0;  // twice the signed area: > 0 when counter-clockwise
    for (std::size_t j = 0; j < ol.size(); ++j) {
        const auto& a = ol[j];
        const auto& b = ol[(j + 1) % ol.size()];
        area2 += a.x() * b.y() - b.x() * a.y();
    }
    if (!(area2 > 0)) throw std::logic_error("part_mesh: the outline is not counter-clockwise");
    Mesh m;
    const std::size_t M = ol.size();
    const auto N = static_cast<std::size_t>(segments);
    m.vertices.reserve(M * N);
    const Matrix3d R = world_from_part.topLeftCorner<3, 3>();
    const Vector3d t = world_from_part.topRightCorner<3, 1>();
    for (std::size_t j = 0; j < M; ++j) {
        for (std::size_t k = 0; k < N; ++k) {
            const double a = 2.0 * kPi * static_cast<double>(k) / static_cast<double>(N);
            const Vector3d p(axis_mm.x() + scale * ol[j].x() * std::cos(a),
                             axis_mm.y() + scale * ol[j].x() * std::sin(a), scale * ol[j].y());
            m.vertices.push_back(R * p + t);
        }
    }
    auto id = [&](std::size_t j, std::size_t k) {
        return static_cast<unsigned>((j % M) * N + (k % N));
    };
    // The outline runs counter-clockwise in the (r, z) half plane: with (j, k), (j+1, k+1),
    // (j+1, k) the normals point out of the solid.
    for (std::size_t j = 0; j < M; ++j) {
        for (std::size_t k = 0; k < N; ++k) {
            m.triangles.push_back({id(j, k), id(j + 1, k + 1), id(j + 1, k)});
            m.triangles.push_back({id(j, k), id(j, k + 1), id(j + 1, k + 1)});
        }
    }
    return m;
}

Mesh plate_mesh() {
    Mesh m;
    m.vertices = {{-kPlateHalf, -kPlateHalf, 0},
                  {kPlateHalf, -kPlateHalf, 0},
                  {kPlateHalf, kPlateHalf, 0},
                  {-kPlateHalf, kPlateHalf, 0}};
    m.triangles = {{{0, 1, 2}}, {{0, 2, 3}}};
    return m;
}

void embree_error(void*, RTCError code, const char* str) {
    std::cerr << "embree error " << static_cast<int>(code) << ": " << (str ? str : "") << "\n";
    std::exit(3);
}

unsigned attach(RTCDevice dev, RTCScene scene, const Mesh& m, unsigned mask) {
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), m.vertices.size()));
    for (std::size_t i = 0; i < m.vertices.size(); ++i)
        for (int c = 0; c < 3; ++c) v[3 * i + c] = static_cast<float>(m.vertices[i][c]);
    auto* ix = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), m.triangles.size()));
    for (std::size_t i = 0; i < m.triangles.size(); ++i)
        for (int c = 0; c < 3; ++c) ix[3 * i + c] = m.triangles[i][c];
    rtcSetGeometryMask(g, mask);
    rtcCommitGeometry(g);
    const unsigned id = rtcAttachGeometry(scene, g);
    rtcReleaseGeometry(g);
    return id;
}

// ---------------------------------------------------------------------------------------------
// Faces

struct Face {
    std::string name;
    Matrix4d camera_to_world;  // at profile position 0 (phase shift included)
    Vector3d scan_direction;
    bool plate = true;
    std::vector<double> positions;
    std::vector<std::int64_t> times;
    std::vector<float> profiles;  // N x W x 2
    std::vector<float> accel;     // K x 3
    std::vector<std::int64_t> accel_times;
    std::size_t hits = 0;
};

Matrix4d pose(const Matrix3d& R, const Vector3d& t) {
    Matrix4d m = Matrix4d::Identity();
    m.topLeftCorner<3, 3>() = R;
    m.topRightCorner<3, 1>() = t;
    return m;
}

Matrix3d columns(const Vector3d& x, const Vector3d& y, const Vector3d& z) {
    Matrix3d R;
    R.col(0) = x;
    R.col(1) = y;
    R.col(2) = z;
    return R;
}

// The camera poses. `ours`: config/cell.yaml's camera_to_world (rotation, x and z translation
// copied; the y translation is the start of this render's scan window). `downDEG` (e.g. down15):
// top and bottom as `ours`; the side sensors look DEG° down with a vertical laser plane, the
// optical axis through the hot flange rim at mid-thickness (nominal part axis at the world origin)
// 890 mm from the camera origin.
std::vector<Face> faces(const std::string& geometry, double y_start, double flange_r_hot,
                        double flange_mid_z_hot) {
    std::vector<Face> f(4);
    f[0].name = "top";
    f[0].camera_to_world =
        pose(columns({1, 0, 0}, {0, -1, 0}, {0, 0, -1}), Vector3d(0, y_start, 930));
    f[1].name = "bottom";
    f[1].camera_to_world = pose(Matrix3d::Identity(), Vector3d(0, y_start, -850));
    f[1].plate = false;
    f[2].name = "side1";
    f[3].name = "side2";
    if (geometry == "ours") {
        f[2].camera_to_world =
            pose(columns({0, 0, 1}, {0, -1, 0}, {1, 0, 0}), Vector3d(-890, y_start, 38));
        f[3].camera_to_world =
            pose(columns({0, 0, 1}, {0, 1, 0}, {-1, 0, 0}), Vector3d(890, y_start, 38));
    } else {
        const double down_deg = std::stod(geometry.substr(4));
        const double c = std::cos(down_deg * kPi / 180.0);
        const double s = std::sin(down_deg * kPi / 180.0);
        for (int side = 0; side < 2; ++side) {
            const double sx = side == 0 ? 1.0 : -1.0;  // side1 at -x looks along +x
            const Vector3d z(sx * c, 0, -s);
            const Vector3d x(sx * s, 0, c);
            const Vector3d y = z.cross(x);
            const Vector3d rim(-sx * flange_r_hot, y_start, flange_mid_z_hot);
            f[2 + side].camera_to_world = pose(columns(x, y, z), rim - kStandoff * z);
        }
    }
    for (auto& face : f) face.scan_direction = Vector3d(0, 1, 0);
    return f;
}

struct Tri {
    Vector3d a, e1, e2, n;  // n: unit normal
};

// Embree tests rays against triangles in single precision: on a seam (a bore's wall meeting a
// parting-plane cap), it may report a triangle that the exact ray passes µm beside (seen: 4 µm on
// a forged part). The context's filter takes a candidate hit only where the double-precision ray
// (Möller–Trumbore) meets the double-precision triangle, so traversal goes on to the true one.
struct ExactContext {
    RTCIntersectContext ctx;  // first: Embree passes &ctx to the filter
    const std::vector<std::vector<Tri>>* tris = nullptr;
    const std::vector<Vector3d>* dir_world = nullptr;  // by ray id
    Vector3d origin = Vector3d::Zero();
};

void exact_filter(const RTCFilterFunctionNArguments* args) {
    const auto* c = reinterpret_cast<const ExactContext*>(args->context);
    constexpr double kTol = 1e-9;  // barycentric: a ray through an edge keeps one side
    for (unsigned i = 0; i < args->N; ++i) {
        if (args->valid[i] == 0) continue;
        const Tri& tri = (*c->tris)[RTCHitN_geomID(args->hit, args->N, i)]
                                   [RTCHitN_primID(args->hit, args->N, i)];
        const Vector3d& d = (*c->dir_world)[RTCRayN_id(args->ray, args->N, i)];
        const Vector3d p = d.cross(tri.e2);
        const double det = tri.e1.dot(p);
        if (std::abs(det) < 1e-300) continue;  // parallel: leave Embree's answer
        const Vector3d s = c->origin - tri.a;
        const double u = s.dot(p) / det;
        const Vector3d q = s.cross(tri.e1);
        const double v = d.dot(q) / det;
        if (u < -kTol || v < -kTol || u + v > 1 + kTol) args->valid[i] = 0;
    }
}

// One face: the fan of W rays per profile, the camera stepping along the scan direction.
// tris: per Embree geometry id, its triangles in double precision.
void render(Face& face, RTCScene scene, const std::vector<std::vector<Tri>>& tris, const Options& o,
            std::uint64_t face_seed) {
    const std::size_t n_prof = face.positions.size();
    face.profiles.assign(n_prof * kWidth * 2, std::numeric_limits<float>::quiet_NaN());
    const Matrix3d R = face.camera_to_world.topLeftCorner<3, 3>();
    const Vector3d T = face.camera_to_world.topRightCorner<3, 1>();
    std::vector<Vector3d> dir_cam(kWidth), dir_world(kWidth);
    for (int i = 0; i < kWidth; ++i) {
        const double x = (i - (kWidth - 1) / 2.0) * kPitch;
        dir_cam[i] = Vector3d(x, 0, kStandoff).normalized();
        dir_world[i] = R * dir_cam[i];
    }
    const double cos_max = std::cos(kMaxIncidenceDeg * kPi / 180.0);
    const unsigned mask = face.plate ? (kMaskPart | kMaskPlate) : kMaskPart;
    std::vector<std::size_t> hits(static_cast<std::size_t>(o.threads), 0);

    auto work = [&](int worker) {
        ExactContext exact;
        rtcInitIntersectContext(&exact.ctx);
        exact.ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
        exact.ctx.filter = exact_filter;
        exact.tris = &tris;
        exact.dir_world = &dir_world;
        alignas(64) RTCRayHit16 rh{};
        alignas(64) int valid[kPacket];
        std::fill(valid, valid + kPacket, -1);
        std::vector<double> gauss_draw(kWidth), unif_draw(kWidth);
        for (std::size_t k = static_cast<std::size_t>(worker); k < n_prof;
             k += static_cast<std::size_t>(o.threads)) {
            // Per-profile generator: the result does not depend on the thread count. Every ray
            // draws its numbers, hit or not, so that the noise of a ray does not depend on what
            // the other rays hit.
            if (o.noise > 0 || o.dropout > 0) {
                std::seed_seq seq{static_cast<std::uint32_t>(face_seed),
                                  static_cast<std::uint32_t>(face_seed >> 32),
                                  static_cast<std::uint32_t>(k)};
                std::mt19937_64 rng(seq);
                std::normal_distribution<double> gauss(0.0, 1.0);
                std::uniform_real_distribution<double> unif(0.0, 1.0);
                for (int i = 0; i < kWidth; ++i) {
                    gauss_draw[i] = gauss(rng);
                    unif_draw[i] = unif(rng);
                }
            }
            const Vector3d origin = T + face.positions[k] * face.scan_direction;
            exact.origin = origin;
            float* row = face.profiles.data() + k * kWidth * 2;
            for (int i0 = 0; i0 < kWidth; i0 += kPacket) {
                for (int l = 0; l < kPacket; ++l) {
                    const Vector3d& d = dir_world[i0 + l];
                    rh.ray.org_x[l] = static_cast<float>(origin.x());
                    rh.ray.org_y[l] = static_cast<float>(origin.y());
                    rh.ray.org_z[l] = static_cast<float>(origin.z());
                    rh.ray.dir_x[l] = static_cast<float>(d.x());
                    rh.ray.dir_y[l] = static_cast<float>(d.y());
                    rh.ray.dir_z[l] = static_cast<float>(d.z());
                    rh.ray.tnear[l] = 0.0f;
                    rh.ray.tfar[l] = std::numeric_limits<float>::infinity();
                    rh.ray.mask[l] = mask;
                    rh.ray.flags[l] = 0;
                    rh.ray.time[l] = 0.0f;
                    rh.ray.id[l] = static_cast<unsigned>(i0 + l);  // exact_filter's direction
                    rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
                    rh.hit.instID[0][l] = RTC_INVALID_GEOMETRY_ID;
                }
                rtcIntersect16(valid, scene, &exact.ctx, &rh);
                for (int l = 0; l < kPacket; ++l) {
                    if (rh.hit.geomID[l] == RTC_INVALID_GEOMETRY_ID) continue;
                    const int i = i0 + l;
                    // Refine in double precision against the exact (double) triangle.
                    const auto& tri = tris[rh.hit.geomID[l]][rh.hit.primID[l]];
                    const Vector3d& d = dir_world[i];
                    const Vector3d p = d.cross(tri.e2);
                    const double det = tri.e1.dot(p);
                    double t = rh.ray.tfar[l];
                    if (std::abs(det) > 1e-12) t = tri.e2.dot((origin - tri.a).cross(tri.e1)) / det;
                    if (std::abs(d.dot(tri.n)) < cos_max) continue;  // incidence > 85°
                    const double range_z = t * dir_cam[i].z();
                    if (range_z < kMinRange || range_z > kMaxRange) continue;
                    if (o.dropout > 0 && unif_draw[i] < o.dropout) continue;
                    if (o.noise > 0) t += o.noise * gauss_draw[i];
                    row[2 * i] = static_cast<float>(t * dir_cam[i].x());
                    row[2 * i + 1] = static_cast<float>(t * dir_cam[i].z());
                    ++hits[static_cast<std::size_t>(worker)];
                }
            }
        }
    };
    std::vector<std::thread> pool;
    for (int w = 1; w < o.threads; ++w) pool.emplace_back(work, w);
    work(0);
    for (auto& th : pool) th.join();
    face.hits = 0;
    for (auto h : hits) face.hits += h;
}

std::vector<Tri> triangles(const Mesh& m) {
    std::vector<Tri> out;
    out.reserve(m.triangles.size());
    for (const auto& t : m.triangles) {
        Tri tr;
        tr.a = m.vertices[t[0]];
        tr.e1 = m.vertices[t[1]] - tr.a;
        tr.e2 = m.vertices[t[2]] - tr.a;
        tr.n = tr.e1.cross(tr.e2).normalized();
        out.push_back(tr);
    }
    return out;
}

// ---------------------------------------------------------------------------------------------
// Writers

std::string shape_text(const std::vector<std::size_t>& shape) {
    std::ostringstream s;
    s << "(";
    for (std::size_t i = 0; i < shape.size(); ++i)
        s << shape[i] << (i + 1 < shape.size() ? ", " : "");
    if (shape.size() == 1) s << ",";
    s << ")";
    return s.str();
}

// NumPy .npy format version 1.0, C order, little-endian.
template <typename T>
void write_npy(const std::filesystem::path& path, const char* descr, const std::vector<T>& data,
               const std::vector<std::size_t>& shape) {
    std::size_t count = 1;
    for (auto s : shape) count *= s;
    if (count != data.size()) throw std::logic_error("npy: shape does not match the data");
    std::string header = std::string("{'descr': '") + descr +
                         "', 'fortran_order': False, 'shape': " + shape_text(shape) + ", }";
    const std::size_t prefix = 10;  // magic (6), version (2), header length (2)
    const std::size_t total = (prefix + header.size() + 1 + 63) / 64 * 64;
    header.append(total - prefix - header.size() - 1, ' ');
    header.push_back('\n');
    if (header.size() > 65535) throw std::logic_error("npy: header too long");
    std::ofstream f(path, std::ios::binary);
    const char magic[] = {'\x93', 'N', 'U', 'M', 'P', 'Y', 1, 0};
    f.write(magic, sizeof magic);
    const auto hl = static_cast<std::uint16_t>(header.size());
    const char len[] = {static_cast<char>(hl & 0xff), static_cast<char>(hl >> 8)};
    f.write(len, 2);
    f.write(header.data(), static_cast<std::streamsize>(header.size()));
    f.write(reinterpret_cast<const char*>(data.data()),
            static_cast<std::streamsize>(data.size() * sizeof(T)));
    if (!f) throw std::runtime_error("cannot write " + path.string());
}

// Shortest text that reads back as the same double; always with a decimal point or exponent.
std::string num(double v) {
    char buf[64];
    const auto res = std::to_chars(buf, buf + sizeof buf, v);
    std::string s(buf, res.ptr);
    if (s.find_first_of(".en") == std::string::npos) s += ".0";
    return s;
}

std::string matrix_text(const Eigen::MatrixXd& m) {
    std::string s = "[";
    for (Eigen::Index r = 0; r < m.rows(); ++r) {
        s += "[";
        for (Eigen::Index c = 0; c < m.cols(); ++c)
            s += num(m(r, c)) + (c + 1 < m.cols() ? ", " : "");
        s += std::string("]") + (r + 1 < m.rows() ? ", " : "");
    }
    return s + "]";
}

std::string json_string(const std::string& v) {
    std::string s = "\"";
    for (char ch : v) {
        if (ch == '"' || ch == '\\') s += '\\';
        s += ch;
    }
    return s + "\"";
}

std::string iso_utc(std::int64_t ns) {
    const std::time_t secs = static_cast<std::time_t>(ns / 1000000000);
    std::tm tm{};
    gmtime_r(&secs, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return buf;
}

void write_text(const std::filesystem::path& path, const std::string& text) {
    std::ofstream f(path);
    f << text;
    if (!f) throw std::runtime_error("cannot write " + path.string());
}

int run(const Options& o) {
    const auto t_start = std::chrono::steady_clock::now();
    const Recipe rc = read_recipe(o.recipe);
    const double dT = o.temperature - 20.0;
    const double alpha = rc.alpha0 + rc.alpha1 * dT;
    const double scale = 1.0 + alpha * dT;
    const double yaw = o.yaw_deg * kPi / 180.0;
    const Matrix3d Rz = Eigen::AngleAxisd(yaw, Vector3d::UnitZ()).toRotationMatrix();
    const Matrix4d world_from_part = pose(Rz, Vector3d(o.x, o.y, 0));

    // Scene: the part's meshes, then the plate; Embree numbers them 0, 1, ... in that order.
    std::optional<Forged> forged;
    std::vector<Mesh> meshes;
    double r_max = 0;
    if (o.forged) {
        // Two closed solids meeting at the parting plane: where their parting-plane annuli
        // overlap, the two caps coincide inside the union and no ray reaches them; elsewhere the
        // uncovered cap is the step the die shift leaves.
        forged = draw_forged(o, scale);
        const core::ForgedPart& fp = forged->part;
        const Eigen::Vector2d shift_hot = scale * fp.shape.die_shift_mm;
        meshes.push_back(part_mesh(fp.lower, o.segments, scale, world_from_part));
        meshes.push_back(part_mesh(fp.upper, o.segments, scale, world_from_part, shift_hot));
        for (const auto& p : fp.lower) r_max = std::max(r_max, p.x());
        for (const auto& p : fp.upper)
            r_max = std::max(r_max, p.x() + fp.shape.die_shift_mm.norm());
    } else {
        const auto ol = outline(rc);
        for (const auto& p : ol) r_max = std::max(r_max, p.x());
        meshes.push_back(part_mesh(ol, o.segments, scale, world_from_part));
    }
    const std::size_t n_part_meshes = meshes.size();
    meshes.push_back(plate_mesh());
    RTCDevice dev = rtcNewDevice(("threads=" + std::to_string(o.threads)).c_str());
    if (!dev) throw std::runtime_error("cannot create the Embree device");
    rtcSetDeviceErrorFunction(dev, embree_error, nullptr);
    RTCScene scene = rtcNewScene(dev);
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_MEDIUM);
    rtcSetSceneFlags(scene, RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION);
    std::vector<std::vector<Tri>> tris;
    std::size_t part_triangles = 0;
    for (std::size_t i = 0; i < meshes.size(); ++i) {
        const bool is_part = i < n_part_meshes;
        if (attach(dev, scene, meshes[i], is_part ? kMaskPart : kMaskPlate) != i)
            throw std::logic_error("Embree geometry ids are not 0, 1, ...");
        tris.push_back(triangles(meshes[i]));
        if (is_part) part_triangles += meshes[i].triangles.size();
    }
    rtcCommitScene(scene);
    const auto t_scene = std::chrono::steady_clock::now();

    // The flange: the outer section with the largest diameter (side sensors aim at its rim).
    const Section* flange = &rc.outer.front();
    for (const auto& s : rc.outer)
        if (s.diameter > flange->diameter) flange = &s;
    const double flange_r_hot = scale * flange->diameter / 2;
    const double flange_mid_hot = scale * (rc.level(flange->from) + rc.level(flange->to)) / 2;

    // Scan window: the part centre ± (hot radius + margin).
    const double half = scale * r_max + kScanMargin;
    const auto n_prof = static_cast<std::size_t>(std::floor(2 * half / kPitch)) + 1;
    std::vector<Face> fs = faces(o.geometry, o.y - half, flange_r_hot, flange_mid_hot);
    std::int64_t t_next = kStartNs;
    for (std::size_t f = 0; f < fs.size(); ++f) {
        Face& face = fs[f];
        // Sub-sample phase: the camera moves by phase * pitch along its own x axis and the
        // profile positions start at phase * spacing.
        face.camera_to_world.topRightCorner<3, 1>() +=
            o.phase * kPitch * face.camera_to_world.block<3, 1>(0, 0);
        face.positions.resize(n_prof);
        face.times.resize(n_prof);
        for (std::size_t k = 0; k < n_prof; ++k) {
            face.positions[k] = (static_cast<double>(k) + o.phase) * kPitch;
            face.times[k] = t_next + static_cast<std::int64_t>(k) * kLinePeriodNs;
        }
        t_next = face.times.back() + kFaceGapNs;
        const Matrix3d R_acc = face.camera_to_world.topLeftCorner<3, 3>();  // accel_to_camera = I
        const Vector3d a = R_acc.transpose() * Vector3d(0, 0, kGravity);
        for (std::int64_t t = face.times.front() - kAccelMarginNs;
             t <= face.times.back() + kAccelMarginNs; t += kAccelPeriodNs) {
            face.accel_times.push_back(t);
            for (int c = 0; c < 3; ++c) face.accel.push_back(static_cast<float>(a[c]));
        }
        render(face, scene, tris, o, o.seed * 4 + f);
    }
    rtcReleaseScene(scene);
    rtcReleaseDevice(dev);
    const auto t_render = std::chrono::steady_clock::now();

    // Recording.
    namespace fsys = std::filesystem;
    const fsys::path out(o.out);
    const fsys::path rec = out / "part";
    fsys::create_directories(rec);
    std::string names;
    for (std::size_t f = 0; f < fs.size(); ++f)
        names += fs[f].name + (f + 1 < fs.size() ? ", " : "");
    std::ostringstream part_yaml;
    part_yaml << "format: hotgauge-recording/1\n"
              << "part_id: " << json_string(o.part_id) << "\n"
              << "recipe: " << rc.name << "\n"
              << "captured_at: \"" << iso_utc(kStartNs) << "\"\n"
              << "temperature_c: " << num(o.temperature) << "\n"
              << "faces: [" << names << "]\n";
    write_text(rec / "part.yaml", part_yaml.str());
    for (const auto& face : fs) {
        const fsys::path d = rec / face.name;
        fsys::create_directories(d);
        std::ostringstream face_yaml;
        face_yaml << "camera_to_world: " << matrix_text(face.camera_to_world) << "\n"
                  << "scan_direction: [" << num(face.scan_direction.x()) << ", "
                  << num(face.scan_direction.y()) << ", " << num(face.scan_direction.z()) << "]\n"
                  << "accel_to_camera: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n";
        write_text(d / "face.yaml", face_yaml.str());
        write_npy(d / "profiles.npy", "<f4", face.profiles,
                  {face.positions.size(), static_cast<std::size_t>(kWidth), 2});
        write_npy(d / "profile_times.npy", "<i8", face.times, {face.times.size()});
        write_npy(d / "profile_positions.npy", "<f8", face.positions, {face.positions.size()});
        write_npy(d / "accel.npy", "<f4", face.accel, {face.accel_times.size(), 3});
        write_npy(d / "accel_times.npy", "<i8", face.accel_times, {face.accel_times.size()});
    }
    write_text(out / "part_pose.yaml", "world_from_part: " + matrix_text(world_from_part) + "\n");

    // Truth: from the mesh's construction (nominal x scale).
    std::ostringstream js;
    js << "{\n  \"generator\": \"hotgauge_oracle_render (Embree " << RTC_VERSION_STRING << ")\",\n"
       << "  \"recipe\": " << json_string(rc.name) << ",\n"
       << "  \"geometry\": " << json_string(o.geometry) << ",\n"
       << "  \"temperature_c\": " << num(o.temperature) << ",\n"
       << "  \"alpha_per_k\": " << num(alpha) << ",\n"
       << "  \"scale\": " << num(scale) << ",\n"
       << "  \"phase\": " << num(o.phase) << ",\n"
       << "  \"noise_mm\": " << num(o.noise) << ",\n"
       << "  \"dropout\": " << num(o.dropout) << ",\n"
       << "  \"seed\": " << o.seed << ",\n"
       << "  \"segments\": " << o.segments << ",\n"
       << "  \"world_from_part\": " << matrix_text(world_from_part) << ",\n"
       << "  \"levels\": {";
    // Forged: the actual levels and each section's diameter at its sharp corner (the anchor of its
    // wall's cone); else the recipe's.
    for (std::size_t i = 0; i < rc.levels.size(); ++i)
        js << (i ? ", " : "") << json_string(rc.levels[i].first) << ": "
           << num(scale * (forged ? forged->part.shape.levels_mm.at(rc.levels[i].first)
                                  : rc.levels[i].second));
    js << "},\n  \"radii\": {";
    bool first = true;
    for (const auto* list : {&rc.outer, &rc.inner})
        for (const auto& s : *list) {
            const double d = forged ? forged->part.shape.diameters_mm.at(s.name) : s.diameter;
            js << (first ? "" : ", ") << json_string(s.name) << ": " << num(scale * d / 2);
            first = false;
        }
    js << "},\n  \"faces\": {";
    for (std::size_t f = 0; f < fs.size(); ++f)
        js << (f ? ", " : "") << json_string(fs[f].name)
           << ": {\"camera_to_world\": " << matrix_text(fs[f].camera_to_world)
           << ", \"profiles\": " << fs[f].positions.size() << ", \"points\": " << fs[f].hits
           << ", \"plate\": " << (fs[f].plate ? "true" : "false") << "}";
    if (forged) {  // the drawn geometry, cold, part frame (docs/simulator.md "As-forged parts")
        const core::ForgedPart& fp = forged->part;
        auto map_text = [](const std::map<std::string, double>& m) {
            std::string t = "{";
            for (const auto& [k, v] : m)
                t += (t.size() > 1 ? ", " : "") + json_string(k) + ": " + num(v);
            return t + "}";
        };
        auto profile_text = [](const core::ForgedSolid::Profile& p) {
            std::string t = "[";
            for (std::size_t i = 0; i < p.size(); ++i)
                t += (i ? ", [" : "[") + num(p[i].x()) + ", " + num(p[i].y()) + "]";
            return t + "]";
        };
        js << "},\n  \"forged\": {\"parting_z_mm\": " << num(fp.parting_z_mm)
           << ", \"die_shift_mm\": [" << num(fp.shape.die_shift_mm.x()) << ", "
           << num(fp.shape.die_shift_mm.y()) << "], \"bad_mm\": " << map_text(forged->bad_mm)
           << ",\n    \"draft_deg\": " << map_text(fp.draft_deg)
           << ",\n    \"fillet_mm\": " << map_text(fp.fillet_mm)
           << ",\n    \"profile_lower\": " << profile_text(fp.lower)
           << ",\n    \"profile_upper\": " << profile_text(fp.upper);
    }
    js << "},\n  \"features\": [\n";
    // Forged: every feature at its theoretical sharp corner and the die shift (core::build_forged),
    // plus "Die shift" when the recipe has no die_shift feature.
    std::vector<std::string> rows;
    for (const Feature& ft : rc.features) {
        double cold = 0.0;
        if (forged) {
            cold = forged->part.feature_cold_mm.at(ft.name);
        } else {  // one solid of revolution: one axis, no die shift
            cold = ft.kind == "diameter" ? rc.section(ft.section).diameter
                   : ft.kind == "height" ? rc.level(ft.to) - rc.level(ft.from)
                                         : 0.0;
            if (std::abs(cold - ft.nominal) > 1e-9)
                std::cerr << "warning: " << ft.name << ": geometry gives " << cold
                          << ", nominal_mm " << ft.nominal << "\n";
        }
        std::string faces_list;
        for (std::size_t k = 0; k < ft.faces.size(); ++k)
            faces_list += (k ? ", " : "") + json_string(ft.faces[k]);
        std::string row = "    {\"name\": " + json_string(ft.name) +
                          ", \"kind\": " + json_string(ft.kind) + ", \"faces\": [" + faces_list +
                          "], \"nominal_cold\": " + num(ft.nominal) +
                          ", \"true_cold\": " + num(cold) + ", \"true_hot\": " + num(scale * cold);
        if (ft.kind == "diameter")
            row += ", \"section\": " + json_string(ft.section);
        else if (ft.kind == "height")
            row += ", \"from\": " + json_string(ft.from) + ", \"to\": " + json_string(ft.to);
        rows.push_back(row + "}");
    }
    if (forged && forged->die_shift_name == "Die shift" &&
        std::none_of(rc.features.begin(), rc.features.end(),
                     [](const Feature& ft) { return ft.name == "Die shift"; })) {
        const double cold = forged->part.shape.die_shift_mm.norm();
        rows.push_back(
            "    {\"name\": \"Die shift\", \"kind\": \"die_shift\", \"faces\": [], "
            "\"nominal_cold\": 0.0, \"true_cold\": " +
            num(cold) + ", \"true_hot\": " + num(scale * cold) + "}");
    }
    for (std::size_t i = 0; i < rows.size(); ++i)
        js << rows[i] << (i + 1 < rows.size() ? "," : "") << "\n";
    js << "  ]\n}\n";
    write_text(out / "truth.json", js.str());
    const auto t_end = std::chrono::steady_clock::now();
    auto ms = [](auto a, auto b) {
        return std::chrono::duration<double, std::milli>(b - a).count();
    };
    std::cerr << "rendered " << fs.size() << " faces x " << n_prof << " profiles x " << kWidth
              << " rays, " << part_triangles << " triangles: " << std::fixed << std::setprecision(0)
              << ms(t_start, t_scene) << " ms scene, " << ms(t_scene, t_render) << " ms rays, "
              << ms(t_render, t_end) << " ms write\n";
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    const Options o = parse(argc, argv);
    try {
        return run(o);
    } catch (const std::exception& e) {
        std::cerr << "hotgauge_oracle_render: " << e.what() << "\n";
        return 1;
    }
}
