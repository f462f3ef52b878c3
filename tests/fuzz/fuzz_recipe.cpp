// Fuzzes io::parse_recipe (config/parts/*.yaml, docs/recipes.md). Input: the whole recipe file,
// named fuzz/recipe.yaml; a file system in which fuzz/hub-a.ply exists, so that a mesh_file
// naming it passes the existence check. Asserts: no crash, sanitizer report or exception
// (parse_recipe promises a core::Result); an error names the file; an accepted recipe has unique
// feature names and slots.
#include <set>

#include "fuzz_util.hpp"
#include "hotgauge/io/recipe.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const io::PathExists exists = fuzz::files_exist({"hub-a.ply"});
    static const auto file = fuzz::kDir / "recipe.yaml";
    auto r = fuzz::no_throw(
        "parse_recipe", [&] { return io::parse_recipe(fuzz::text_of(data, size), file, exists); });
    if (!r) {
        fuzz::check_error_names(r.error(), file);
        return 0;
    }
    std::set<std::string> names;
    std::set<int> slots;
    for (const auto& f : r->features)
        fuzz::check(names.insert(f.name).second && slots.insert(f.slot).second,
                    "a feature name or slot is used twice");
    return 0;
}
