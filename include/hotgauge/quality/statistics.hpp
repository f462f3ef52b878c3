#pragma once
// The quality engineer's statistics (issue 19, docs/quality.md): process capability, the
// individuals / moving-range chart, and the type-1 and type-3 gauge studies. Pure functions on
// plain values; input they cannot judge (too few values, a tolerance that is not positive,
// non-finite values, no spread) is an Error naming what is wrong, never a NaN result.
#include <cstddef>
#include <span>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::quality {

// Capability of individual values against [lsl, usl] (ISO 22514-2, AIAG SPC): Cp, Cpk with the
// within σ of the moving ranges (MR̄ / d2, d2 = 1.128), Pp, Ppk with the overall sample σ.
struct Capability {
    std::size_t n = 0;
    double mean = 0, s_overall = 0, s_within = 0;
    double cp = 0, cpk = 0, pp = 0, ppk = 0;
};
core::Result<Capability> capability(std::span<const double> x, double lsl, double usl);

// Individuals and moving-range chart limits from a baseline: centre x̄, x̄ ± 3·σ (σ = MR̄/d2), the
// moving range's upper limit D4·MR̄ (D4 = 3.267; its lower limit is 0).
struct IndividualsChart {
    double centre = 0, lcl = 0, ucl = 0;
    double sigma = 0;  // the within σ the limits come from: MR̄/d2
    double mr_bar = 0, mr_ucl = 0;
};
core::Result<IndividualsChart> individuals_chart(std::span<const double> baseline);

// Western Electric rules on an individuals chart (AT&T Statistical Quality Control Handbook,
// 1956; Nelson rules 1, 5, 6 and 2 with 8 points), zones of the chart's within σ about its
// centre. A violation is marked on the point that completes it, and only when that point is
// itself in the zone the rule names (beyond 2σ for rule 2 …, on the side for rule 4).
//   1: one point beyond 3σ;
//   2: 2 of 3 consecutive points beyond 2σ on the same side;
//   3: 4 of 5 consecutive points beyond 1σ on the same side;
//   4: 8 consecutive points on the same side of the centre.
struct RuleViolation {
    std::size_t index = 0;  // in x
    int rule = 0;           // 1 … 4
};
std::vector<RuleViolation> western_electric(std::span<const double> x, double centre, double sigma);

// Type-1 gauge study (VDA 5, Bosch booklet 10): repeated measurements of one reference part.
// Cg = 0.2·T / (6·s), Cgk = (0.1·T − |x̄ − reference|) / (3·s); the bias's significance by
// Student's t (two-sided, n − 1 degrees of freedom); the resolution as a share of T (at most
// 5 % to pass).
struct Type1Study {
    std::size_t n = 0;
    double mean = 0, s = 0, bias = 0;
    double cg = 0, cgk = 0;
    double t = 0, p_value = 1;    // bias / (s/√n) and its two-sided p
    double resolution_share = 0;  // resolution / T
};
core::Result<Type1Study> type1_study(std::span<const double> x, double reference, double tolerance,
                                     double resolution);

// Type-3 gauge study (an automatic gauge, no operator): n parts each measured r times; one-way
// ANOVA with the part as factor. EV = √MS_within (repeatability = GRR), PV = √((MS_parts −
// MS_within)/r) (0 when negative), TV = √(GRR² + PV²); %GRR of TV and of the tolerance (6·GRR/T),
// ndc = ⌊1.41·PV/GRR⌋.
struct Type3Study {
    std::size_t parts = 0, repeats = 0;
    double ms_parts = 0, ms_within = 0;
    double grr = 0, pv = 0, tv = 0;
    double grr_percent_tv = 0, grr_percent_tolerance = 0;
    int ndc = 0;
};
core::Result<Type3Study> type3_study(const std::vector<std::vector<double>>& by_part,
                                     double tolerance);

}  // namespace hotgauge::quality
