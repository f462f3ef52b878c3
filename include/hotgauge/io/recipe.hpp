#pragma once
// Reading part recipes (config/parts/*.yaml, docs/recipes.md).
#include <filesystem>

#include "hotgauge/core/part.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/io/bytes.hpp"

namespace hotgauge::io {

// Reads and validates a recipe. Errors name file:line and the key; unknown keys are errors;
// references (levels, sections, faces) and nominal values are checked against the geometry.
core::Result<core::Recipe> read_recipe(const std::filesystem::path& file);
// The same on the file's text: `file` names it in errors and is the folder a relative mesh_file
// is found in; `exists` is asked whether that mesh file exists.
core::Result<core::Recipe> parse_recipe(std::string_view text, const std::filesystem::path& file,
                                        const PathExists& exists = exists_on_disk);

}  // namespace hotgauge::io
