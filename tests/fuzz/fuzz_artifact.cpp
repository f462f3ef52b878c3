// Fuzzes calib::parse_artifact (a calibration artifact's file, docs/calibration.md). Input: the
// whole file, named fuzz/artifact.yaml. Asserts: no crash, sanitizer report or exception
// (parse_artifact promises a core::Result); an error names the file; an accepted artifact has at
// least 3 spheres of positive diameter, none overlapping another, and unit plane normals.
#include <cmath>

#include "fuzz_util.hpp"
#include "hotgauge/calib/artifact.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const auto file = fuzz::kDir / "artifact.yaml";
    auto a = fuzz::no_throw("parse_artifact",
                            [&] { return calib::parse_artifact(fuzz::text_of(data, size), file); });
    if (!a) {
        fuzz::check_error_names(a.error(), file);
        return 0;
    }
    fuzz::check(a->spheres.size() >= 3, "an artifact with fewer than 3 spheres");
    for (std::size_t i = 0; i < a->spheres.size(); ++i) {
        const auto& s = a->spheres[i];
        fuzz::check(s.diameter_mm > 0.0 && s.center_mm.allFinite(), "a sphere's invariants");
        for (std::size_t j = 0; j < i; ++j)
            fuzz::check((a->spheres[j].center_mm - s.center_mm).norm() >=
                            0.5 * (a->spheres[j].diameter_mm + s.diameter_mm),
                        "two spheres overlap");
    }
    for (const auto& p : a->planes)
        fuzz::check(std::abs(p.normal.norm() - 1.0) < 1e-9, "a plane normal is not a unit vector");
    return 0;
}
