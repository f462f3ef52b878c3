#pragma once
// A forging's recipe as its drawing's idealisation (sharp corners, vertical walls, one axis): no
// `forging` notes, every feature from the first face it lists (a diameter's edge face, a side
// height's side scan), no die shift. What a recipe without `forging` measures (docs/recipes.md);
// the tests of the estimators of that idealisation use it.
#include "hotgauge/core/part.hpp"

namespace hotgauge::test {

inline core::Recipe idealised(core::Recipe r) {
    r.forging.reset();
    std::vector<core::FeatureSpec> kept;
    for (auto f : r.features) {
        if (f.kind == core::FeatureKind::kDieShift) continue;
        if (f.kind == core::FeatureKind::kDiameter || f.height_method == core::HeightMethod::kEdges)
            f.faces.resize(1);
        kept.push_back(f);
    }
    r.features = kept;
    return r;
}

}  // namespace hotgauge::test
