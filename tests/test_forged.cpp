// As-forged parts (docs/simulator.md "As-forged parts"): the forged solid's ray hits against
// closed forms (a drafted wall, a fillet, the die shift's step), the ideal forging against
// AxisymmetricSolid, the features at the theoretical sharp corners against the surface the rays
// see, and the simulator's truth with --forged and --bad.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "hotgauge/core/forged.hpp"
#include "hotgauge/core/geometry.hpp"
#include "hotgauge/core/part.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/sim/scene.hpp"
#include "hotgauge/sim/simulator.hpp"

using namespace hotgauge;

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

const core::Recipe& hub_a() {
    static const core::Recipe r = [] {
        auto rr = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
        EXPECT_TRUE(rr) << (rr ? "" : rr.error().message);
        return *rr;
    }();
    return r;
}

// hub-a with every wall drafted `draft_deg`, every corner filleted `fillet_mm`.
core::ForgedShape drafted(double draft_deg, double fillet_mm,
                          Eigen::Vector2d shift = Eigen::Vector2d::Zero()) {
    core::ForgedShape s;
    for (const auto& w : core::forged_walls(hub_a())) s.draft_deg[w.name] = draft_deg;
    for (const auto& c : core::forged_corners(hub_a())) s.fillet_mm[c.name] = fillet_mm;
    s.die_shift_mm = shift;
    return s;
}

core::ForgedPart build(const core::ForgedShape& shape) {
    auto p = core::build_forged(hub_a(), shape);
    EXPECT_TRUE(p) << (p ? "" : p.error().message);
    return *p;
}

// The surface point a horizontal ray from −x at height z meets (part frame).
double outer_r_at(const core::ForgedSolid& s, double z, double y = 0.0) {
    auto h = s.intersect({-500, y, z}, {1, 0, 0}, 1e4);
    EXPECT_TRUE(h);
    return h ? 500.0 - h->t : 0.0;
}

}  // namespace

TEST(ForgedShape, WallsAndCornersOfHubA) {
    std::vector<std::string> walls, corners;
    for (const auto& w : core::forged_walls(hub_a())) walls.push_back(w.name);
    for (const auto& c : core::forged_corners(hub_a())) corners.push_back(c.name);
    // Nine walls (the flange rim and the through bore cross the parting plane), 14 corners.
    EXPECT_EQ(walls.size(), 9u);
    EXPECT_NE(std::find(walls.begin(), walls.end(), "flange lower"), walls.end());
    EXPECT_NE(std::find(walls.begin(), walls.end(), "through bore upper"), walls.end());
    EXPECT_EQ(corners.size(), 14u);
    EXPECT_NE(std::find(corners.begin(), corners.end(), "bore_step inner"), corners.end());
    EXPECT_NE(std::find(corners.begin(), corners.end(), "boss_top outer"), corners.end());
}

// A drafted wall is the cone anchored at the feature's sharp corner: a horizontal ray meets the
// spigot wall at r = 31.25 + tanθ·(z − 8) (narrower going down to the spigot step), the boss
// wall at r = 34.75 − tanθ·(z − 76.2) (narrower going up), with the cone's normal.
TEST(ForgedSolid, DraftedWallsAreTheAnchoredCones) {
    const double theta = 2.5 * kDeg;
    const auto part = build(drafted(2.5, 0.0));
    const auto solid = part.solid();
    for (const double z : {12.0, 30.0, 45.0})
        EXPECT_NEAR(outer_r_at(solid, z), 31.25 + std::tan(theta) * (z - 8.0), 1e-9) << z;
    for (const double z : {64.0, 70.0, 75.0})
        EXPECT_NEAR(outer_r_at(solid, z), 34.75 - std::tan(theta) * (z - 76.2), 1e-9) << z;
    auto h = solid.intersect({-500, 0, 30}, {1, 0, 0}, 1e4);
    ASSERT_TRUE(h);
    EXPECT_NEAR(h->normal.x(), -std::cos(theta), 1e-12);  // outward and down
    EXPECT_NEAR(h->normal.z(), -std::sin(theta), 1e-12);
    // A ray at a slant, from above, onto the boss wall: the point solves the cone exactly.
    const Eigen::Vector3d o(-300, 40, 250), target(-33.0, 5.0, 70.0);
    const Eigen::Vector3d d = (target - o).normalized();
    h = solid.intersect(o, d, 1e4);
    ASSERT_TRUE(h);
    const Eigen::Vector3d p = o + h->t * d;
    EXPECT_NEAR(std::hypot(p.x(), p.y()), 34.75 - std::tan(theta) * (p.z() - 76.2), 1e-9);
    // Bores widen toward the die face they open to: the bottom bore at the spigot end is its
    // diameter, narrower above; the recess at the boss top is its diameter, narrower below.
    h = solid.intersect({0, 0, 20}, {1, 0, 0}, 1e4);
    ASSERT_TRUE(h);
    EXPECT_NEAR(h->t, 13.85 - std::tan(theta) * 20.0, 1e-9);
    h = solid.intersect({0, 0, 74}, {0, 1, 0}, 1e4);
    ASSERT_TRUE(h);
    EXPECT_NEAR(h->t, 27.3 - std::tan(theta) * (76.2 - 74.0), 1e-9);
    EXPECT_NEAR(h->normal.y(), -std::cos(theta), 1e-12);  // out of the material, into the recess
}

// A vertical ray onto the boss top's outer fillet lands on the circle tangent to the boss wall
// (draft θ) and the top face, within the chords' sag (< 5 µm).
TEST(ForgedSolid, FilletIsTheTangentCircle) {
    const double theta = 2.0 * kDeg, rho = 2.0;
    const auto part = build(drafted(2.0, rho));
    EXPECT_NEAR(part.fillet_mm.at("boss_top outer"), rho, 1e-12);
    const auto solid = part.solid();
    // Corner V = (34.75, 76.2); the circle's centre lies ρ below the top and ρ inside the wall.
    const double zc = 76.2 - rho;
    const double rc = 34.75 - std::tan(theta) * (zc - 76.2) - rho / std::cos(theta);
    // The fillet spans r from rc to rc + ρ·cosθ (where it meets the wall).
    double worst = 0;
    for (double f = 0.05; f < 0.95; f += 0.05) {
        const double r = rc + f * rho * std::cos(theta);
        auto h = solid.intersect({r, 0, 200}, {0, 0, -1}, 1e4);
        ASSERT_TRUE(h) << r;
        const double z_exact = zc + std::sqrt(rho * rho - (r - rc) * (r - rc));
        const double err = z_exact - (200.0 - h->t);  // chords lie inside the arc
        EXPECT_GE(err, -1e-9) << r;
        worst = std::max(worst, err);
    }
    EXPECT_LT(worst, 0.005);
    EXPECT_GT(worst, 1e-5) << "not a fillet of chords: the ray missed the rounded corner";
    // Outside the fillet: the flat top at z 76.2.
    auto h = solid.intersect({rc - 0.5, 0, 200}, {0, 0, -1}, 1e4);
    ASSERT_TRUE(h);
    EXPECT_NEAR(200.0 - h->t, 76.2, 1e-9);
}

// Draft 0, fillets 0, no shift: the same part as AxisymmetricSolid, ray for ray.
TEST(ForgedSolid, IdealForgingIsTheAxisymmetricSolid) {
    core::ForgedShape shape;
    shape.levels_mm = {{"spigot_step", 8.03}, {"flange_top", 61.95}, {"boss_top", 76.27}};
    shape.diameters_mm = {{"boss", 69.43}, {"through bore", 24.35}};
    shape.scale = 1.0155;
    const auto forged = build(shape).solid();
    const auto ideal = core::AxisymmetricSolid::from_recipe(hub_a(), shape.levels_mm,
                                                            shape.diameters_mm, shape.scale);
    std::mt19937_64 rng(11);
    std::normal_distribution<double> g(0, 1);
    int hits = 0;
    for (int i = 0; i < 20000; ++i) {
        const Eigen::Vector3d o(150 * g(rng), 150 * g(rng), 40 + 80 * g(rng));
        const Eigen::Vector3d target(40 * g(rng), 40 * g(rng), 40 + 25 * g(rng));
        const Eigen::Vector3d d = (target - o).normalized();
        const auto a = forged.intersect(o, d, 1e4);
        const auto b = ideal.intersect(o, d, 1e4);
        ASSERT_EQ(a.has_value(), b.has_value()) << i;
        if (!a) continue;
        ++hits;
        ASSERT_NEAR(a->t, b->t, 1e-9) << i;
        ASSERT_NEAR((a->normal - b->normal).norm(), 0.0, 1e-9) << i;
        const Eigen::Vector3d p = o + a->t * d;
        ASSERT_NEAR(forged.distance(p), 0.0, 1e-9);
        ASSERT_NEAR(forged.distance(p + 0.3 * d), ideal.distance(p + 0.3 * d), 1e-9);
        EXPECT_EQ(forged.inside(p + 1e-4 * d),
                  ideal.inside(std::hypot(p.x() + 1e-4 * d.x(), p.y() + 1e-4 * d.y()),
                               p.z() + 1e-4 * d.z()));
    }
    EXPECT_GT(hits, 5000);
}

// Random rays on a drafted, filleted, shifted part: the hit lies on the surface, arrives against
// the normal, from outside into the material.
TEST(ForgedSolid, RandomRaysHitTheSurfaceFromOutside) {
    const auto solid = build(drafted(2.5, 2.0, {0.3, -0.2})).solid();
    std::mt19937_64 rng(5);
    std::normal_distribution<double> g(0, 1);
    int hits = 0;
    for (int i = 0; i < 20000; ++i) {
        const Eigen::Vector3d o(150 * g(rng), 150 * g(rng), 40 + 80 * g(rng));
        const Eigen::Vector3d target(40 * g(rng), 40 * g(rng), 40 + 25 * g(rng));
        const Eigen::Vector3d d = (target - o).normalized();
        const auto h = solid.intersect(o, d, 1e4);
        if (!h) continue;
        ++hits;
        const Eigen::Vector3d p = o + h->t * d;
        ASSERT_LT(solid.distance(p), 1e-7) << i;
        if (-h->normal.dot(d) < 0.05) continue;  // grazing: 1e-5 along the ray is not across
        ASSERT_LT(h->normal.dot(d), 1e-12) << i;
        ASSERT_NEAR(h->normal.norm(), 1.0, 1e-12);
        ASSERT_FALSE(solid.inside(p - 1e-5 * d)) << i;
        ASSERT_TRUE(solid.inside(p + 1e-5 * d)) << i;
    }
    EXPECT_GT(hits, 5000);
}

// The die shift moves every upper-half hit by d and no lower-half hit, and leaves a step on the
// parting plane where one half's annulus is not covered by the other's.
TEST(ForgedSolid, DieShiftMovesTheUpperHalf) {
    const Eigen::Vector2d d(0.4, 0.25);
    const auto centred = build(drafted(2.0, 1.5)).solid();
    const auto shifted = build(drafted(2.0, 1.5, d)).solid();
    const Eigen::Vector3d d3(d.x(), d.y(), 0);
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> u(-1, 1);
    for (int i = 0; i < 2000; ++i) {
        // Rays from above aimed at the boss, recess and flange top (the upper half).
        const Eigen::Vector3d o(300 * u(rng), 300 * u(rng), 200 + 100 * u(rng));
        const Eigen::Vector3d target(40 * u(rng), 40 * u(rng), 66 + 8 * u(rng));
        const Eigen::Vector3d dir = (target - o).normalized();
        const auto a = centred.intersect(o, dir, 1e4);
        if (!a || (o + a->t * dir).z() < 56.0) continue;
        const auto b = shifted.intersect(o + d3, dir, 1e4);
        ASSERT_TRUE(b);
        ASSERT_NEAR(a->t, b->t, 1e-9);
        ASSERT_NEAR((a->normal - b->normal).norm(), 0.0, 1e-9);
    }
    // Lower half (the spigot): unmoved.
    EXPECT_NEAR(outer_r_at(shifted, 30.0), outer_r_at(centred, 30.0), 1e-12);
    // Upper half (the boss), seen from −x along a line through its own axis.
    EXPECT_NEAR(outer_r_at(shifted, 70.0, d.y()), outer_r_at(centred, 70.0) - d.x(), 1e-9);
    // The step: on −x the lower half's rim reaches beyond the upper one's, and its top face
    // there is seen from above on the parting plane; without the shift the drafted rim is met.
    const double zp = shifted.parting_z_mm();
    const double rim = outer_r_at(centred, zp - 1e-3);
    const Eigen::Vector3d o(-(rim - 0.1), 0, 100);
    const auto h = shifted.intersect(o, {0, 0, -1}, 1e4);
    ASSERT_TRUE(h);
    EXPECT_NEAR(100.0 - h->t, zp, 1e-9);
    EXPECT_NEAR(h->normal.z(), 1.0, 1e-12);
    const auto h0 = centred.intersect(o, {0, 0, -1}, 1e4);
    ASSERT_TRUE(h0);
    EXPECT_GT(100.0 - h0->t, zp + 1.0);
    // From below on +x the upper half's overhang faces down.
    const auto under = shifted.intersect({rim + 0.1, 0, 0}, {0, 0, 1}, 1e4);
    ASSERT_TRUE(under);
    EXPECT_NEAR(under->t, zp, 1e-9);
    EXPECT_NEAR(under->normal.z(), -1.0, 1e-12);
}

// Each diameter at its theoretical sharp corner: the wall cone the rays see, extended to the
// level plane the rays see, meets it at half the feature's value; heights between the planes.
TEST(ForgedPart, FeaturesAtTheSharpCornersAreWhatTheSurfaceSays) {
    core::ForgedShape shape = drafted(0.0, 0.0, {0.2, 0.1});
    std::mt19937_64 rng(17);
    std::uniform_real_distribution<double> draft(1.0, 3.0), fillet(1.0, 2.5);
    for (auto& [name, v] : shape.draft_deg) v = draft(rng);
    for (auto& [name, v] : shape.fillet_mm) v = fillet(rng);
    shape.fillet_mm["bore_step inner"] = shape.fillet_mm["bore_step outer"] = 0.3;
    shape.draft_deg["bottom bore"] = 1.0;  // keep the bore step's ring
    shape.levels_mm["boss_top"] = 76.9;
    shape.diameters_mm["boss"] = 70.2;
    const auto part = build(shape);
    const auto solid = part.solid();
    // Diameter 3: the boss wall (two horizontal rays, clear of fillets) and the boss top.
    const Eigen::Vector2d axis = shape.die_shift_mm;
    auto wall_r = [&](double z) { return outer_r_at(solid, z, axis.y()) + axis.x(); };
    const double z1 = 65.0, z2 = 73.0, r1 = wall_r(z1), r2 = wall_r(z2);
    auto top = solid.intersect({axis.x() + 31.0, axis.y(), 200}, {0, 0, -1}, 1e4);
    ASSERT_TRUE(top);
    const double z_top = 200.0 - top->t;
    const double r_corner = r1 + (r2 - r1) * (z_top - z1) / (z2 - z1);
    EXPECT_NEAR(z_top, 76.9, 1e-9);
    EXPECT_NEAR(2.0 * r_corner, 70.2, 1e-9);
    EXPECT_NEAR(part.feature_cold_mm.at("Diameter 3"), 2.0 * r_corner, 1e-9);
    EXPECT_NEAR((r1 - r2) / (z2 - z1), std::tan(shape.draft_deg.at("boss") * kDeg), 1e-9);
    // Diameter 1: the flange rim below the parting plane, extended to the flange underside.
    const double f1 = outer_r_at(solid, 51.5), f2 = outer_r_at(solid, 54.5);
    auto under = solid.intersect({66.0, 0, -100}, {0, 0, 1}, 1e4);
    ASSERT_TRUE(under);
    const double z_under = under->t - 100.0;
    EXPECT_NEAR(part.feature_cold_mm.at("Diameter 1"),
                2.0 * (f1 + (f2 - f1) * (z_under - 51.5) / 3.0), 1e-9);
    EXPECT_NEAR(part.feature_cold_mm.at("Diameter 1"), 138.4, 1e-9);
    // Diameter 7: the through bore above the parting plane at the recess floor (its own axis).
    auto bore = [&](double z) {
        return solid.intersect({axis.x(), axis.y(), z}, {1, 0, 0}, 1e4)->t;
    };
    const double b1 = bore(60.0), b2 = bore(68.0);
    EXPECT_NEAR(part.feature_cold_mm.at("Diameter 7"), 2.0 * (b1 + (b2 - b1) * (71.2 - 60) / 8),
                1e-9);
    EXPECT_NEAR(part.feature_cold_mm.at("Diameter 7"), 24.3, 1e-9);
    EXPECT_NEAR(part.feature_cold_mm.at("Height 4 side1"), 76.9, 1e-12);
    EXPECT_NEAR(part.feature_cold_mm.at("Height 3 side1"), 62.0 - 48.3, 1e-12);
    // The parting plane keeps its place between the flange's faces.
    EXPECT_NEAR(part.parting_z_mm, 55.15, 1e-12);
}

// A fillet is cut down where a face is narrow: at most 0.4 of the face it rounds onto.
TEST(ForgedPart, FilletsFitNarrowFaces) {
    core::ForgedShape shape = drafted(0.0, 2.5);
    shape.diameters_mm["through bore"] = 26.7;  // bore step ring 0.5 mm wide
    const auto part = build(shape);
    EXPECT_NEAR(part.fillet_mm.at("bore_step inner"), 0.2, 1e-9);
    EXPECT_NEAR(part.fillet_mm.at("bore_step outer"), 0.2, 1e-9);
    EXPECT_NEAR(part.fillet_mm.at("boss_top outer"), 2.5, 1e-12);
}

TEST(ForgedPart, RecipeWithoutStackedSectionsIsAnError) {
    core::Recipe r = hub_a();
    std::swap(r.outer[1], r.outer[2]);
    auto p = core::build_forged(r, {});
    ASSERT_FALSE(p);
    EXPECT_NE(p.error().message.find("stacked"), std::string::npos) << p.error().message;
}

namespace {

sim::CellConfig quick_cell() {
    auto c = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
    EXPECT_TRUE(c) << (c ? "" : c.error().message);
    return sim::quick(*c);
}

core::Result<sim::SimTruth> truth_of(const sim::SimOptions& opt,
                                     const core::Recipe& recipe = hub_a()) {
    std::mt19937_64 rng(opt.seed);
    auto scene = sim::Scene::create(recipe, quick_cell(), opt, rng);
    if (!scene) return scene.error();
    return scene->truth();
}

sim::SimOptions forged_options(std::uint64_t seed) {
    sim::SimOptions opt;
    opt.seed = seed;
    opt.temperature_c = 1050.0;
    opt.forged = true;
    return opt;
}

double feature(const sim::SimTruth& t, const std::string& name, bool hot = false) {
    for (const auto& f : t.features)
        if (f.name == name) return hot ? f.hot_mm : f.cold_mm;
    ADD_FAILURE() << "no feature " << name;
    return 0.0;
}

}  // namespace

// The truth of a drawn part: every feature at its sharp corner (the drawn dimension), the die
// shift as the 14th, hot = cold × growth; drafts, fillets and shift within the drawing.
TEST(SimulateForged, TruthIsTheSharpCornersAndTheDieShift) {
    for (const std::uint64_t seed : {1u, 2u, 3u, 4u, 5u, 6u, 7u, 8u}) {
        SCOPED_TRACE(seed);
        auto t = truth_of(forged_options(seed));
        ASSERT_TRUE(t) << t.error().message;
        ASSERT_TRUE(t->forged);
        const core::ForgedPart& part = *t->forged;
        ASSERT_EQ(t->features.size(), 14u);
        EXPECT_EQ(t->features.back().name, "Die shift");
        const double shift = part.shape.die_shift_mm.norm();
        EXPECT_NEAR(feature(*t, "Die shift"), shift, 1e-15);
        EXPECT_NEAR(feature(*t, "Die shift", true), shift * t->growth, 1e-15);
        EXPECT_LE(shift, 0.8 * 0.5);
        for (const auto& f : hub_a().features) {
            EXPECT_DOUBLE_EQ(feature(*t, f.name, true), feature(*t, f.name) * t->growth);
            if (f.kind == core::FeatureKind::kDiameter) {
                EXPECT_NEAR(feature(*t, f.name), t->diameters_mm.at(f.section), 1e-9) << f.name;
            }
        }
        // The sharp profile has each diameter's corner on its level plane.
        for (const auto& f : hub_a().features) {
            if (f.kind != core::FeatureKind::kDiameter) continue;
            const double z = t->levels_mm.at(f.edge_at), r = 0.5 * feature(*t, f.name);
            int found = 0;
            for (const auto* prof : {&part.lower_sharp, &part.upper_sharp})
                for (const auto& q : *prof)
                    found += std::abs(q.x() - r) < 1e-9 && std::abs(q.y() - z) < 1e-12;
            EXPECT_GE(found, 1) << f.name;
        }
        EXPECT_EQ(part.draft_deg.size(), 9u);
        for (const auto& [wall, deg] : part.draft_deg) {
            EXPECT_GE(deg, 1.0) << wall;
            EXPECT_LE(deg, 3.0) << wall;
        }
        for (const auto& [corner, r] : part.fillet_mm) {
            EXPECT_LE(r, part.shape.fillet_mm.at(corner)) << corner;
            EXPECT_LE(r, 2.5) << corner;
        }
        for (const auto& [level, width] : part.level_faces_mm)
            if (level == "bore_step") {
                EXPECT_GT(width, 0.3);
                EXPECT_LE(part.fillet_mm.at("bore_step inner"), 0.4 * width + 1e-12);
            }
    }
}

// The forged draws have their own stream: the same seed, the same dimensions and pose.
TEST(SimulateForged, SameSeedSameDimensionsAndPose) {
    auto forged = truth_of(forged_options(9));
    sim::SimOptions plain = forged_options(9);
    plain.forged = false;
    auto drawn = truth_of(plain);
    ASSERT_TRUE(forged && drawn);
    EXPECT_EQ(forged->levels_mm, drawn->levels_mm);
    EXPECT_EQ(forged->diameters_mm, drawn->diameters_mm);
    EXPECT_TRUE(forged->T_world_part.isApprox(drawn->T_world_part, 0.0));
    EXPECT_FALSE(drawn->forged);
    EXPECT_EQ(drawn->features.size(), hub_a().features.size());
}

// --bad moves the chosen feature's truth by exactly its delta, and the rendered surface with it.
TEST(SimulateForged, BadFeatureMovesTheTruthAndTheSurface) {
    sim::SimOptions opt = forged_options(21);
    auto good = truth_of(opt);
    opt.bad_mm = {{"Diameter 3", 0.7}, {"Height 1", -0.4}};
    auto bad = truth_of(opt);
    ASSERT_TRUE(good && bad) << (bad ? "" : bad.error().message);
    EXPECT_NEAR(feature(*bad, "Diameter 3") - feature(*good, "Diameter 3"), 0.7, 1e-12);
    EXPECT_NEAR(feature(*bad, "Height 1") - feature(*good, "Height 1"), -0.4, 1e-12);
    for (const char* same :
         {"Diameter 1", "Diameter 5", "Diameter 7", "Height 2", "Height 4 side1", "Die shift"})
        EXPECT_NEAR(feature(*bad, same), feature(*good, same), 1e-12) << same;
    EXPECT_EQ(bad->bad_mm.at("Diameter 3"), 0.7);
    // The boss wall, seen from −x through its own axis: 0.35 mm (hot: × growth) farther out.
    auto outer = [](const sim::SimTruth& t) {
        const Eigen::Vector2d a = t.growth * t.forged->shape.die_shift_mm;
        return 500.0 -
               t.forged->solid().intersect({-500, a.y(), 70.0 * t.growth}, {1, 0, 0}, 1e4)->t +
               a.x();
    };
    EXPECT_NEAR(outer(*bad) - outer(*good), 0.35 * bad->growth, 1e-9);
    // The die shift can be made bad too (forged only).
    opt.bad_mm = {{"Die shift", 0.3}};
    auto shifted = truth_of(opt);
    ASSERT_TRUE(shifted);
    EXPECT_NEAR(feature(*shifted, "Die shift") - feature(*good, "Die shift"), 0.3, 1e-12);
}

TEST(SimulateForged, ClearErrors) {
    sim::SimOptions opt = forged_options(1);
    opt.bad_mm = {{"Diameter 9", 0.5}};
    auto t = truth_of(opt);
    ASSERT_FALSE(t);
    EXPECT_NE(t.error().message.find("'Diameter 9'"), std::string::npos) << t.error().message;
    opt.bad_mm.clear();
    core::Recipe no_drawing = hub_a();
    no_drawing.forging.reset();
    t = truth_of(opt, no_drawing);
    ASSERT_FALSE(t);
    EXPECT_NE(t.error().message.find("forging"), std::string::npos) << t.error().message;
    opt.forged = false;
    opt.bad_mm = {{"Die shift", 0.2}};
    t = truth_of(opt);
    ASSERT_FALSE(t);
    EXPECT_NE(t.error().message.find("--forged"), std::string::npos) << t.error().message;
}

// What the sensor sees is the forged part: with the true vibration added every non-spike point
// lies on the forged solid or the support within 5σ; many are off the drawing's sharp solid.
TEST(SimulateForged, ScannedPointsLieOnTheForgedPart) {
    sim::SimOptions opt = forged_options(401);
    opt.t0_ns = 1'790'000'000'000'000'000;
    const sim::CellConfig cell = quick_cell();
    auto r = sim::simulate(hub_a(), cell, opt);
    ASSERT_TRUE(r) << r.error().message;
    const sim::SimTruth& t = r->truth;
    const auto forged = t.forged->solid();
    const auto sharp = t.solid(hub_a());
    const Eigen::Isometry3d T_part_world = t.T_world_part.inverse();
    const double tol = 5.0 * t.range_noise_mm;
    std::int64_t on_part = 0, off_sharp = 0, off = 0;
    for (std::size_t j = 0; j < r->recording.faces.size(); ++j) {
        const auto& face = r->recording.faces[j];
        const auto& ft = t.faces[j];
        const auto cloud = core::world_cloud(face, &ft.displacement_mm);
        for (std::size_t q = 0; q < cloud.points_mm.size(); ++q) {
            if (ft.spike[cloud.profile[q] * face.width + cloud.column[q]]) continue;
            const Eigen::Vector3d pw = cloud.points_mm[q], p = T_part_world * pw;
            const double h = t.support_half_size_mm;
            const double dx = std::max(std::abs(pw.x()) - h, 0.0);
            const double dy = std::max(std::abs(pw.y()) - h, 0.0);
            const double support = std::sqrt(dx * dx + dy * dy + pw.z() * pw.z());
            const double d = forged.distance(p);
            if (d <= tol) {
                ++on_part;
                off_sharp += sharp.distance(p) > 0.3;
            } else if (support > tol) {
                ++off;
            }
        }
    }
    EXPECT_EQ(off, 0);
    EXPECT_GT(on_part, 30000);
    EXPECT_GT(off_sharp, on_part / 100) << "the forged part looks like the sharp one";
}
