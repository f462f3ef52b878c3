// The forged corner's profile (src/measure/corner.cpp): samples drawn on a known plane, fillet and
// drafted wall, seen along vertical rays with range noise, fitted back.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "../src/measure/corner.hpp"

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

}  // namespace
}  // namespace hotgauge::measure::detail
