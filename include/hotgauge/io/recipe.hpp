#pragma once
// Reading part recipes (config/parts/*.yaml, docs/recipes.md).
#include <filesystem>

#include "hotgauge/core/part.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::io {

// Reads and validates a recipe. Errors name file:line and the key; unknown keys are errors;
// references (levels, sections, faces) and nominal values are checked against the geometry.
core::Result<core::Recipe> read_recipe(const std::filesystem::path& file);

}  // namespace hotgauge::io
