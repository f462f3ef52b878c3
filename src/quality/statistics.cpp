#include "hotgauge/quality/statistics.hpp"

#include <algorithm>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <numeric>
#include <string>

namespace hotgauge::quality {
namespace {

constexpr double kD2 = 1.128;  // E[range of 2 normal values] / σ
constexpr double kD4 = 3.267;  // moving range's upper limit factor, subgroups of 2

std::string count(std::size_t n) { return std::to_string(n); }

core::Result<void> check_values(std::span<const double> x, std::size_t min_n, const char* what) {
    if (x.size() < min_n)
        return core::make_error(std::string(what) + ": need at least " + count(min_n) +
                                " values, got " + count(x.size()));
    for (std::size_t i = 0; i < x.size(); ++i)
        if (!std::isfinite(x[i]))
            return core::make_error(std::string(what) + ": value " + count(i + 1) +
                                    " is not finite");
    return {};
}

double mean_of(std::span<const double> x) {
    return std::accumulate(x.begin(), x.end(), 0.0) / static_cast<double>(x.size());
}

double sample_std(std::span<const double> x, double mean) {
    double s2 = 0;
    for (double v : x) s2 += (v - mean) * (v - mean);
    return std::sqrt(s2 / static_cast<double>(x.size() - 1));
}

double mean_moving_range(std::span<const double> x) {
    double sum = 0;
    for (std::size_t i = 1; i < x.size(); ++i) sum += std::abs(x[i] - x[i - 1]);
    return sum / static_cast<double>(x.size() - 1);
}

// The within σ of individual values: MR̄ / d2.
double within_sigma(double mr_bar) { return mr_bar / kD2; }

}  // namespace

core::Result<Capability> capability(std::span<const double> x, double lsl, double usl) {
    if (auto ok = check_values(x, 2, "capability"); !ok) return ok.error();
    if (!(usl > lsl))
        return core::make_error("capability: the upper limit " + std::to_string(usl) +
                                " is not above the lower limit " + std::to_string(lsl));
    Capability c;
    c.n = x.size();
    c.mean = mean_of(x);
    c.s_overall = sample_std(x, c.mean);
    c.s_within = within_sigma(mean_moving_range(x));
    if (!(c.s_overall > 0) || !(c.s_within > 0))
        return core::make_error("capability: the values do not vary (" + count(x.size()) +
                                " equal values, or no change from one to the next)");
    const double nearest = std::min(usl - c.mean, c.mean - lsl);
    c.cp = (usl - lsl) / (6.0 * c.s_within);
    c.cpk = nearest / (3.0 * c.s_within);
    c.pp = (usl - lsl) / (6.0 * c.s_overall);
    c.ppk = nearest / (3.0 * c.s_overall);
    return c;
}

core::Result<IndividualsChart> individuals_chart(std::span<const double> baseline) {
    if (auto ok = check_values(baseline, 2, "control limits"); !ok) return ok.error();
    IndividualsChart c;
    c.centre = mean_of(baseline);
    c.mr_bar = mean_moving_range(baseline);
    c.sigma = within_sigma(c.mr_bar);
    if (!(c.sigma > 0))  // rules and drift are in units of σ: limits of width 0 judge nothing
        return core::make_error("control limits: the values do not change from one to the next");
    c.lcl = c.centre - 3.0 * c.sigma;
    c.ucl = c.centre + 3.0 * c.sigma;
    c.mr_ucl = kD4 * c.mr_bar;
    return c;
}

namespace {

// Whether at least `need` of the `window` points ending at i lie beyond `zones` σ on the side
// `side` (+1 above the centre, −1 below), point i among them.
bool zone_rule(std::span<const double> z, std::size_t i, std::size_t window, std::size_t need,
               double zones, int side) {
    if (i + 1 < window || side * z[i] <= zones) return false;
    std::size_t beyond = 0;
    for (std::size_t k = i + 1 - window; k <= i; ++k) beyond += side * z[k] > zones ? 1 : 0;
    return beyond >= need;
}

}  // namespace

std::vector<RuleViolation> western_electric(std::span<const double> x, double centre,
                                            double sigma) {
    std::vector<double> z(x.size());  // in σ from the centre
    for (std::size_t i = 0; i < x.size(); ++i) z[i] = (x[i] - centre) / sigma;
    std::vector<RuleViolation> out;
    for (std::size_t i = 0; i < z.size(); ++i) {
        if (std::abs(z[i]) > 3.0) out.push_back({i, 1});
        for (int side : {1, -1}) {
            if (zone_rule(z, i, 3, 2, 2.0, side)) out.push_back({i, 2});
            if (zone_rule(z, i, 5, 4, 1.0, side)) out.push_back({i, 3});
            if (zone_rule(z, i, 8, 8, 0.0, side)) out.push_back({i, 4});
        }
    }
    return out;
}

core::Result<Type1Study> type1_study(std::span<const double> x, double reference, double tolerance,
                                     double resolution) {
    if (auto ok = check_values(x, 2, "type-1 study"); !ok) return ok.error();
    if (!(tolerance > 0) || !std::isfinite(tolerance))
        return core::make_error("type-1 study: the tolerance must be positive, got " +
                                std::to_string(tolerance));
    if (!(resolution >= 0) || !std::isfinite(reference))
        return core::make_error(
            "type-1 study: the reference and resolution must be finite, "
            "the resolution not negative");
    Type1Study t;
    t.n = x.size();
    t.mean = mean_of(x);
    t.s = sample_std(x, t.mean);
    if (!(t.s > 0))
        return core::make_error("type-1 study: all " + count(x.size()) +
                                " values are equal: the gauge's resolution is too coarse to "
                                "see its repeatability");
    t.bias = t.mean - reference;
    t.cg = 0.2 * tolerance / (6.0 * t.s);
    t.cgk = (0.1 * tolerance - std::abs(t.bias)) / (3.0 * t.s);
    t.t = t.bias / (t.s / std::sqrt(static_cast<double>(t.n)));
    const boost::math::students_t dist(static_cast<double>(t.n - 1));
    t.p_value = 2.0 * boost::math::cdf(boost::math::complement(dist, std::abs(t.t)));
    t.resolution_share = resolution / tolerance;
    return t;
}

core::Result<Type3Study> type3_study(const std::vector<std::vector<double>>& by_part,
                                     double tolerance) {
    if (by_part.size() < 2)
        return core::make_error("type-3 study: need at least 2 parts, got " +
                                count(by_part.size()));
    if (!(tolerance > 0) || !std::isfinite(tolerance))
        return core::make_error("type-3 study: the tolerance must be positive, got " +
                                std::to_string(tolerance));
    const std::size_t r = by_part.front().size();
    for (std::size_t i = 0; i < by_part.size(); ++i) {
        if (by_part[i].size() != r)
            return core::make_error("type-3 study: part " + count(i + 1) + " has " +
                                    count(by_part[i].size()) + " measurements, part 1 has " +
                                    count(r) + " (a balanced study needs the same for each)");
        if (auto ok = check_values(by_part[i], 2, "type-3 study"); !ok)
            return core::make_error(ok.error().message + " (part " + count(i + 1) + ")");
    }
    Type3Study s;
    s.parts = by_part.size();
    s.repeats = r;
    double grand = 0, ss_parts = 0, ss_within = 0;
    std::vector<double> means;
    for (const auto& p : by_part) means.push_back(mean_of(p));
    grand = mean_of(means);
    for (std::size_t i = 0; i < by_part.size(); ++i) {
        ss_parts += static_cast<double>(r) * (means[i] - grand) * (means[i] - grand);
        for (double v : by_part[i]) ss_within += (v - means[i]) * (v - means[i]);
    }
    const auto n = static_cast<double>(s.parts);
    s.ms_parts = ss_parts / (n - 1.0);
    s.ms_within = ss_within / (n * (static_cast<double>(r) - 1.0));
    s.grr = std::sqrt(s.ms_within);
    s.pv = std::sqrt(std::max(0.0, (s.ms_parts - s.ms_within) / static_cast<double>(r)));
    s.tv = std::hypot(s.grr, s.pv);
    if (!(s.grr > 0))
        return core::make_error(
            "type-3 study: the repeated measurements do not vary: the "
            "gauge's resolution is too coarse to see its repeatability");
    s.grr_percent_tv = 100.0 * s.grr / s.tv;
    s.grr_percent_tolerance = 100.0 * 6.0 * s.grr / tolerance;
    s.ndc = static_cast<int>(std::floor(1.41 * s.pv / s.grr));
    return s;
}

}  // namespace hotgauge::quality
