// AxisymmetricSolid against closed-form cases: boundary, distance, ray intersection.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "hotgauge/core/part.hpp"
#include "hotgauge/io/recipe.hpp"

using hotgauge::core::AxisymmetricSolid;

namespace {

// A stepped shaft with a bore: outer r 10 (z 0..5), r 20 (z 5..10); bore r 4 through.
AxisymmetricSolid stepped() { return AxisymmetricSolid({{0, 5, 10}, {5, 10, 20}}, {{0, 10, 4}}); }

}  // namespace

TEST(AxisymmetricSolid, BoundaryOfSteppedShaft) {
    const auto s = stepped();
    // Expected faces: bottom annulus r 4..10, step annulus r 10..20 at z 5, top annulus 4..20 at
    // z 10 (split at r 10 by the candidate grid), cylinders r 10, r 20, bore r 4 (split at z 5).
    double bottom = 0, step = 0, top = 0, cyl10 = 0, cyl20 = 0, bore = 0;
    for (const auto& seg : s.boundary()) {
        const double len = seg.hi - seg.lo;
        if (!seg.cylinder && seg.value == 0) bottom += len;
        if (!seg.cylinder && seg.value == 5) step += len;
        if (!seg.cylinder && seg.value == 10) top += len;
        if (seg.cylinder && seg.value == 10) cyl10 += len;
        if (seg.cylinder && seg.value == 20) cyl20 += len;
        if (seg.cylinder && seg.value == 4) bore += len;
    }
    EXPECT_DOUBLE_EQ(bottom, 6);
    EXPECT_DOUBLE_EQ(step, 10);
    EXPECT_DOUBLE_EQ(top, 16);
    EXPECT_DOUBLE_EQ(cyl10, 5);
    EXPECT_DOUBLE_EQ(cyl20, 5);
    EXPECT_DOUBLE_EQ(bore, 10);
}

TEST(AxisymmetricSolid, DistanceClosedForm) {
    const auto s = stepped();
    EXPECT_NEAR(s.distance({15, 0, 7}), 2.0, 1e-12);  // inside the flange: z 5 is nearest
    EXPECT_NEAR(s.distance({0, 25, 8}), 5.0, 1e-12);  // outside, beside the r 20 cylinder
    EXPECT_NEAR(s.distance({0, 0, 2}), 4.0, 1e-12);   // on the axis, in the bore
    EXPECT_NEAR(s.distance({3, 4, 12}), 2.0, 1e-12);  // r 5 above the top face
    EXPECT_NEAR(s.distance({13, 0, 3}), 2.0, 1e-12);  // below the step (2), beside r 10 (3)
}

TEST(AxisymmetricSolid, RayHitsAndNormals) {
    const auto s = stepped();
    // Straight down at r 15: hits the top face z 10 at t 90, normal +z.
    auto h = s.intersect({15, 0, 100}, {0, 0, -1}, 1e3);
    ASSERT_TRUE(h);
    EXPECT_NEAR(h->t, 90.0, 1e-12);
    EXPECT_NEAR(h->normal.z(), 1.0, 1e-12);
    // Straight up at r 15 from below: hits the step underside z 5, normal −z.
    h = s.intersect({0, 15, -100}, {0, 0, 1}, 1e3);
    ASSERT_TRUE(h);
    EXPECT_NEAR(h->t, 105.0, 1e-12);
    EXPECT_NEAR(h->normal.z(), -1.0, 1e-12);
    // Horizontal at z 2 from −x: hits r 10 cylinder at x = −10, normal −x.
    h = s.intersect({-100, 0, 2}, {1, 0, 0}, 1e3);
    ASSERT_TRUE(h);
    EXPECT_NEAR(h->t, 90.0, 1e-12);
    EXPECT_NEAR(h->normal.x(), -1.0, 1e-12);
    // Down the bore: passes through.
    EXPECT_FALSE(s.intersect({0, 1, 100}, {0, 0, -1}, 1e3));
    // t_max respected.
    EXPECT_FALSE(s.intersect({15, 0, 100}, {0, 0, -1}, 80));
}

TEST(AxisymmetricSolid, RandomRaysHitTheSurface) {
    const auto s = stepped();
    std::mt19937_64 rng(7);
    std::normal_distribution<double> g(0, 1);
    int hits = 0;
    for (int i = 0; i < 20000; ++i) {
        const Eigen::Vector3d o(40 * g(rng), 40 * g(rng), 60 + 10 * g(rng));
        const Eigen::Vector3d target(10 * g(rng), 10 * g(rng), 5 + 3 * g(rng));
        const Eigen::Vector3d d = (target - o).normalized();
        auto h = s.intersect(o, d, 1e3);
        if (!h) continue;
        ++hits;
        const Eigen::Vector3d p = o + h->t * d;
        ASSERT_LT(s.distance(p), 1e-9) << "hit point off the surface";
        // The ray arrives from outside: it travels against the outward normal.
        ASSERT_LT(h->normal.dot(d), 1e-12);
    }
    EXPECT_GT(hits, 2000);
}

TEST(AxisymmetricSolid, HubAFromRecipe) {
    auto r = hotgauge::io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
    ASSERT_TRUE(r) << r.error().message;
    const auto s = AxisymmetricSolid::from_recipe(*r, {}, {}, 1.01);
    EXPECT_NEAR(s.height(), 76.2 * 1.01, 1e-9);
    EXPECT_NEAR(s.max_radius(), 69.2 * 1.01, 1e-9);
    // Boss top face at r 30 (between recess 27.3 and boss 34.75), scaled.
    auto h = s.intersect({30 * 1.01, 0, 200}, {0, 0, -1}, 1e3);
    ASSERT_TRUE(h);
    EXPECT_NEAR(200 - h->t, 76.2 * 1.01, 1e-9);
    // Recess floor at r 20.
    h = s.intersect({20 * 1.01, 0, 200}, {0, 0, -1}, 1e3);
    ASSERT_TRUE(h);
    EXPECT_NEAR(200 - h->t, 71.2 * 1.01, 1e-9);
    // From below at r 13 (inside the bottom bore 13.85, outside the through bore 12.15): bore step.
    h = s.intersect({13.0 * 1.01, 0, -100}, {0, 0, 1}, 1e3);
    ASSERT_TRUE(h);
    EXPECT_NEAR(h->t - 100, 39.3 * 1.01, 1e-9);
}
