#include "hotgauge/core/recording.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace hotgauge::core {

std::string describe(const std::string& face, const UntrustedProfiles& u) {
    char b[160];
    std::snprintf(b, sizeof b, "%s profiles %lld–%lld (%.3f–%.3f s): ", face.c_str(),
                  static_cast<long long>(u.first), static_cast<long long>(u.last), u.t0_s, u.t1_s);
    return b + u.cause;
}

double DisplacementNoise::cov(int axis, double tau_s) const {
    const std::vector<double>& c = acov_mm2[static_cast<std::size_t>(axis)];
    if (!known()) return 0.0;
    const double x = std::abs(tau_s) / lag_s;
    const auto i = static_cast<std::size_t>(x);
    if (i + 1 >= c.size()) return i + 1 == c.size() ? c[i] : 0.0;
    const double f = x - static_cast<double>(i);
    return c[i] + f * (c[i + 1] - c[i]);
}

double DisplacementNoise::hole_sigma(std::size_t hole, double t_s) const {
    const auto& [t0, t1] = holes_s[hole];
    const double d = std::max({0.0, t0 - t_s, t_s - t1});
    for (const auto& [upto, sigma] : hole_sigma_mm)
        if (d <= upto) return sigma;
    return 0.0;
}

}  // namespace hotgauge::core
