// The forged corner's profile (src/measure/corner.cpp): samples drawn on a known plane, fillet and
// drafted wall, seen along vertical rays with range noise, fitted back.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include "../src/measure/corner.hpp"
#include "../src/measure/drift.hpp"

namespace hotgauge::measure::detail {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// A point of the profile at arc length `u` from the plane's far end (plane, then fillet, then
// wall), in (s, h).
Eigen::Vector2d on_profile(const CornerModel& m, double plane_len, double u) {
    const double k = std::sqrt(1.0 + m.t * m.t);
    const Eigen::Vector2d c(-m.rho * k + m.t * m.rho, -m.rho);
    const double s_c = c.x();
    if (u < plane_len) return {s_c - plane_len + u, 0.0};
    u -= plane_len;
    const double a0 = std::numbers::pi / 2, a1 = std::atan2(m.t / k, 1.0 / k);  // normals
    const double arc = m.rho * (a0 - a1);
    if (u < arc) {
        const double a = a0 - u / m.rho;
        return c + m.rho * Eigen::Vector2d(std::cos(a), std::sin(a));
    }
    u -= arc;
    const Eigen::Vector2d T2 = c + m.rho * Eigen::Vector2d(std::cos(a1), std::sin(a1));
    return T2 + u * Eigen::Vector2d(m.t / k, -1.0 / k);
}

// n samples around the whole circle, the range noise along h (a sensor looking along the axis).
std::vector<CornerPoint> samples(const CornerModel& m, double side, int n, double sigma,
                                 std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::normal_distribution<double> noise(0.0, sigma);
    const double plane_len = 3.0, total = plane_len + 2.0 * m.rho + 6.0;
    std::vector<CornerPoint> out;
    for (int j = 0; j < n; ++j) {
        const Eigen::Vector2d sh = on_profile(m, plane_len, total * u01(rng));
        const double phi = 2.0 * std::numbers::pi * u01(rng);
        const double r = m.radius + side * sh.x();
        out.push_back(
            {m.centre + r * Eigen::Vector2d(std::cos(phi), std::sin(phi)), sh.y() + noise(rng)});
    }
    return out;
}

TEST(CornerProfile, ResidualIsZeroOnTheProfileAndPositiveBeyondIt) {
    const CornerModel m{{0.3, -0.2}, 30.0, std::tan(2.0 * kDeg), 1.5};
    int parts[3] = {0, 0, 0};
    for (double u = 0.0; u < 12.0; u += 0.01) {
        const Eigen::Vector2d sh = on_profile(m, 3.0, u);
        const CornerPoint p{m.centre + Eigen::Vector2d(m.radius + sh.x(), 0.0), sh.y()};
        int part = -1;
        EXPECT_NEAR(corner_residual(m, 1.0, p, &part), 0.0, 1e-9) << u;
        parts[part]++;
        const CornerPoint beyond{p.q + Eigen::Vector2d(0.05, 0.0), p.h + 0.05};
        EXPECT_GT(corner_residual(m, 1.0, beyond, nullptr), 0.0) << u;
    }
    for (int part : parts) EXPECT_GT(part, 50);  // plane, fillet and wall all visited
}

struct Case {
    double side, t_deg, rho;
};

TEST(CornerProfile, RecoversTheSharpCornerOfDraftedFilletedEdges) {
    std::mt19937_64 rng(36);
    for (const Case& k :
         {Case{1.0, 2.0, 1.8}, Case{-1.0, 2.7, 1.4}, Case{1.0, 1.0, 2.4}, Case{-1.0, 3.0, 0.6}}) {
        const CornerModel truth{{0.12, -0.08}, 27.75, std::tan(k.t_deg * kDeg), k.rho};
        const auto pts = samples(truth, k.side, 20000, 0.0, rng);
        CornerModel start{{0.0, 0.0}, truth.radius + 0.4, std::tan(1.5 * kDeg), 1.25};
        const auto fit = fit_corner(pts, k.side, start, {std::tan(3.0 * kDeg), 2.5});
        EXPECT_NEAR(fit.m.radius, truth.radius, 1e-4) << k.side << " " << k.t_deg;
        EXPECT_NEAR(fit.m.rho, truth.rho, 1e-3);
        EXPECT_NEAR(std::atan(fit.m.t) / kDeg, k.t_deg, 0.02);
        EXPECT_NEAR((fit.m.centre - truth.centre).norm(), 0.0, 1e-4);
        EXPECT_GT(fit.n_arc, 1000);
        EXPECT_GT(fit.n_wall, 1000);
    }
}

TEST(CornerProfile, NoisySamplesKeepTheCornerWithinItsUncertainty) {
    std::mt19937_64 rng(7);
    const CornerModel truth{{0.0, 0.0}, 35.25, std::tan(2.1 * kDeg), 1.76};
    int covered = 0;
    for (int trial = 0; trial < 10; ++trial) {
        const auto pts = samples(truth, 1.0, 20000, 0.05, rng);
        const auto fit = fit_corner(pts, 1.0, {{0.1, 0.1}, 35.0, std::tan(1.5 * kDeg), 1.25},
                                    {std::tan(3.0 * kDeg), 2.5});
        EXPECT_NEAR(fit.m.radius, truth.radius, 0.005);
        covered += std::abs(fit.m.radius - truth.radius) <= 2.0 * fit.u_radius;
    }
    EXPECT_GE(covered, 8);  // k = 2
}

// A wall the plane's sensor loses (only the plane and the fillet seen): fitted once at the
// drawing's draft, then refitted from there with the draft the side scans give (refit_draft),
// it lands where a whole fit with that draft does, and on the true corner.
TEST(CornerProfile, ARefitWithTheSideDraftEqualsAWholeFit) {
    std::mt19937_64 rng(17);
    for (const Case& k : {Case{1.0, 2.6, 1.8}, Case{1.0, 1.1, 2.3}, Case{-1.0, 2.9, 1.2}}) {
        const CornerModel truth{{0.05, -0.03}, 31.6, std::tan(k.t_deg * kDeg), k.rho};
        auto pts = samples(truth, k.side, 30000, 0.0, rng);
        std::erase_if(pts, [&](const CornerPoint& p) { return p.h < -(k.rho + 0.1); });
        for (std::size_t q = 0; q < pts.size(); ++q) pts[q].profile = static_cast<int>(q % 97);
        CornerPrior drawing{std::tan(3.0 * kDeg), 2.5};
        drawing.fix_draft = true;
        const CornerModel start{{0.0, 0.0}, truth.radius + 0.1, drawing.t_mean(), 1.25};
        const CornerFit held = fit_corner(pts, k.side, start, drawing);
        CornerPrior side = drawing;
        side.t_known = truth.t;
        side.t_known_u = 1e-4;
        const CornerFit refit = refit_draft(pts, k.side, held, side);
        const CornerFit whole = fit_corner(pts, k.side, start, side);
        std::printf("draft %.1f°: at the drawing's %+.4f mm, refit %+.6f, whole fit %+.6f\n",
                    k.t_deg, held.m.radius - truth.radius, refit.m.radius - truth.radius,
                    whole.m.radius - truth.radius);
        EXPECT_GT(std::abs(held.m.radius - truth.radius), 0.005);  // the draft matters here
        EXPECT_NEAR(refit.m.radius, whole.m.radius, 2e-5);
        EXPECT_NEAR(refit.m.radius, truth.radius, 5e-4);
        // Exact samples: the held draft's u (the prior's, 1e-4) is gone, and what is left is the
        // jackknife kept from the fit at the drawing's draft (its misfit: 0.01-0.04 µm).
        EXPECT_LT(refit.u_radius, 1e-4);
        EXPECT_EQ(refit.radial.size(), whole.radial.size());
    }
}

TEST(CornerProfile, ASharpVerticalEdgeFitsWithoutAFillet) {
    std::mt19937_64 rng(3);
    const CornerModel truth{{0.0, 0.0}, 12.15, 0.0, 0.0};
    std::vector<CornerPoint> pts;
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    for (int j = 0; j < 20000; ++j) {  // plane to 3 mm inside, wall to 5 mm down
        const double phi = 2.0 * std::numbers::pi * u01(rng), a = u01(rng);
        const double s = j % 2 ? -3.0 * a : 0.0, h = j % 2 ? 0.0 : -5.0 * a;
        pts.push_back({(truth.radius - s) * Eigen::Vector2d(std::cos(phi), std::sin(phi)), h});
    }
    const auto fit = fit_corner(pts, -1.0, {{0.0, 0.0}, 12.0, std::tan(1.5 * kDeg), 1.25},
                                {std::tan(3.0 * kDeg), 2.5});
    EXPECT_LT(fit.m.rho, 0.05);
    EXPECT_NEAR(fit.m.radius, truth.radius, 1e-3);
}

// A short step (hub-a's recess): plane, fillet, wall, the far fillet and the far level, by arc
// length u from the plane's far end; `skip_wall`: the wall's own stretch left out (the sensor
// looking along the axis does not see it), u running over the rest.
Eigen::Vector2d on_step(const CornerModel& m, double u, bool skip_wall) {
    const double k = std::sqrt(1.0 + m.t * m.t), plane_len = 3.0;
    const Eigen::Vector2d n2(1.0 / k, m.t / k), down(m.t / k, -1.0 / k);
    const Eigen::Vector2d c1(-m.rho * k + m.t * m.rho, -m.rho);
    const Eigen::Vector2d c2(m.rho2 * k + m.t * (m.depth - m.rho2), m.rho2 - m.depth);
    const double a1 = std::atan2(m.t / k, 1.0 / k);
    const Eigen::Vector2d T1 = c1 + m.rho * n2, T2 = c2 - m.rho2 * n2;
    const double arc1 = m.rho * (std::numbers::pi / 2 - a1), wall = (T2 - T1).dot(down);
    const double arc2 = m.rho2 * (std::numbers::pi / 2 - a1);
    if (u < plane_len) return {c1.x() - plane_len + u, 0.0};
    if ((u -= plane_len) < arc1) {
        const double a = std::numbers::pi / 2 - u / m.rho;
        return c1 + m.rho * Eigen::Vector2d(std::cos(a), std::sin(a));
    }
    u -= arc1;
    if (!skip_wall && u < wall) return T1 + u * down;
    if (!skip_wall) u -= wall;
    if (u < arc2) {
        const double a = std::numbers::pi + a1 + u / m.rho2;
        return c2 + m.rho2 * Eigen::Vector2d(std::cos(a), std::sin(a));
    }
    return {c2.x() + (u - arc2), -m.depth};
}

TEST(CornerProfile, StepResidualIsZeroOnItsProfileAndPositiveOutOfTheMaterial) {
    CornerModel m{{0.0, 0.0}, 27.7, std::tan(2.8 * kDeg), 2.1};
    m.depth = 5.1;
    m.rho2 = 1.15;
    int parts[5] = {0, 0, 0, 0, 0};
    for (double u = 0.0; u < 12.0; u += 0.005) {
        const Eigen::Vector2d sh = on_step(m, u, false);
        const CornerPoint p{Eigen::Vector2d(m.radius - sh.x(), 0.0), sh.y()};  // a bore
        int part = -1;
        EXPECT_NEAR(corner_residual(m, -1.0, p, &part), 0.0, 1e-9) << u;
        parts[part]++;
        const CornerPoint above{p.q, p.h + 0.02};  // out of the material, towards the sensor
        EXPECT_GT(corner_residual(m, -1.0, above, nullptr), 0.0) << u;
    }
    for (int part : parts) EXPECT_GT(part, 20);  // every piece of the profile visited
}

// The wall of a short step unseen: the two fillets, both tangent to it, fix its draft.
TEST(CornerProfile, AStepsTwoFilletsFixTheDraftOfAWallNotSeen) {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::normal_distribution<double> noise(0.0, 0.05);
    CornerModel truth{{0.05, -0.03}, 27.7, std::tan(2.8 * kDeg), 2.1};
    truth.depth = 5.1;
    truth.rho2 = 1.15;
    CornerPrior prior{std::tan(3.0 * kDeg), 2.5};
    prior.depth = 5.0;  // the drawing's, not the part's
    double mean_error = 0;
    for (int trial = 0; trial < 10; ++trial) {
        std::vector<CornerPoint> pts;
        for (int j = 0; j < 20000; ++j) {
            const Eigen::Vector2d sh = on_step(truth, 12.0 * u01(rng), true);
            const double phi = 2.0 * std::numbers::pi * u01(rng), r = truth.radius - sh.x();
            const double sigma = trial == 0 ? 0.0 : 1.0;
            pts.push_back({truth.centre + r * Eigen::Vector2d(std::cos(phi), std::sin(phi)),
                           sh.y() + sigma * noise(rng), Eigen::Vector2d(0.0, 1.0)});
        }
        const auto fit =
            fit_corner(pts, -1.0, {{0.0, 0.0}, 27.5, std::tan(1.5 * kDeg), 1.25}, prior);
        EXPECT_LT(fit.n_wall, 200);  // the tangent points' noise only
        EXPECT_GT(fit.n_far, 5000);
        if (trial == 0) {  // exact samples: the exact corner, though the wall was never seen
            EXPECT_NEAR(fit.m.radius, truth.radius, 2e-4);
            EXPECT_NEAR(std::atan(fit.m.t) / kDeg, 2.8, 0.01);
            EXPECT_NEAR(fit.m.rho2, truth.rho2, 1e-3);
            EXPECT_NEAR(fit.m.depth, truth.depth, 1e-4);
            continue;
        }
        // σ 0.05 mm: 2 µm large on the mean of the 9 (6 µm small while grazing rays fell back
        // to the bare orthogonal distance, corner.cpp).
        EXPECT_NEAR(fit.m.radius, truth.radius, 0.015);
        EXPECT_NEAR(std::atan(fit.m.t) / kDeg, 2.8, 0.4);
        mean_error += (fit.m.radius - truth.radius) / 9.0;
    }
    std::printf("step corner, 9 noisy trials: mean radius error %+.4f mm\n", mean_error);
    EXPECT_LT(std::abs(mean_error), 0.01);
}

}  // namespace
}  // namespace hotgauge::measure::detail

// The compensation's own error in a weighted sum of samples (drift.hpp): one face's error e(t)
// with σ 2 µm along world z, correlated 0.5 at 10 ms and not at all at 20 ms.
TEST(CompensationDrift, SumsOverProfilesWithTheErrorsCovariance) {
    using namespace hotgauge;
    core::FaceScan scan;
    for (int k = 0; k < 5; ++k) scan.profile_times_ns.push_back(1'000'000'000 + k * 10'000'000);
    core::DisplacementNoise noise;
    noise.lag_s = 0.01;
    noise.acov_mm2 = {std::vector<double>{0, 0, 0}, std::vector<double>{0, 0, 0},
                      std::vector<double>{4e-6, 2e-6, 0.0}};
    measure::detail::FaceFrame fr;
    fr.scan = &scan;
    fr.n = 5;
    fr.M = Eigen::Matrix3d::Identity();
    fr.noise = &noise;
    const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
    {
        measure::detail::DriftSum d;  // one profile: σ
        d.add(fr, 2, z);
        EXPECT_NEAR(d.u(), 2e-3, 1e-12);
    }
    {
        measure::detail::DriftSum d;  // a difference 10 ms apart: √(4 + 4 − 2·2) µm
        d.add(fr, 1, z);
        d.add(fr, 2, -z);
        EXPECT_NEAR(d.u(), 2e-3, 1e-12);
    }
    {
        measure::detail::DriftSum d;  // 20 ms apart: independent, √8 µm; along x: nothing
        d.add(fr, 0, z);
        d.add(fr, 2, -z);
        d.add(fr, 3, Eigen::Vector3d::UnitX());
        EXPECT_NEAR(d.u(), std::sqrt(8.0) * 1e-3, 1e-12);
    }
    {
        // M = R_part_world · R_world_camera. The part turned so that its y is the world's z,
        // seen by a camera turned about z: a part-frame y weight is world z, its z weight is not.
        const Eigen::Matrix3d R_part_world =
            Eigen::AngleAxisd(-std::numbers::pi / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
        ASSERT_TRUE((R_part_world.transpose() * Eigen::Vector3d::UnitY()).isApprox(z));
        const Eigen::Matrix3d R_world_camera =
            Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
        scan.T_world_camera.linear() = R_world_camera;
        fr.M = R_part_world * R_world_camera;
        measure::detail::DriftSum d;
        d.add(fr, 2, 0.5 * Eigen::Vector3d::UnitY());
        d.add(fr, 3, z);
        EXPECT_NEAR(d.u(), 1e-3, 1e-12);
    }
    {
        // A diameter (add_radial): 4 samples of one profile, all pointing along e1 = part y =
        // world z: the diameter moves by twice their error, 2σ; a full ring of them, not at all.
        measure::detail::DriftSum d;
        const Eigen::Vector3d e1 = Eigen::Vector3d::UnitY(), e2 = Eigen::Vector3d::UnitX();
        measure::detail::add_radial(d, fr, 2, Eigen::Vector2d(4.0, 0.0), e1, e2, 4.0);
        EXPECT_NEAR(d.u(), 4e-3, 1e-12);
        measure::detail::DriftSum ring;
        for (int q = 0; q < 8; ++q) {
            const double a = q * std::numbers::pi / 4;
            measure::detail::add_radial(ring, fr, 2, {std::cos(a), std::sin(a)}, e1, e2, 8.0);
        }
        EXPECT_NEAR(ring.u(), 0.0, 1e-9);
    }
    {
        measure::detail::DriftSum d;  // a face without a noise model adds nothing
        fr.noise = nullptr;
        d.add(fr, 2, z);
        EXPECT_EQ(d.u(), 0.0);
    }
}
