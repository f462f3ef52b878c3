// Fuzzes io::read_recipe (config/parts/*.yaml, docs/recipes.md). Input: the whole recipe file.
// An empty hub-a.ply sits beside it, so that a mesh_file naming it passes the existence check.
// Asserts: no crash, sanitizer report or exception (read_recipe promises a core::Result); an
// error names the file; an accepted recipe has unique feature names and slots.
#include <set>

#include "fuzz_util.hpp"
#include "hotgauge/io/recipe.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const auto mesh = fuzz::input_file("recipe", "hub-a.ply", nullptr, 0);
    (void)mesh;
    const auto file = fuzz::input_file("recipe", "recipe.yaml", data, size);
    auto r = fuzz::no_throw("read_recipe", [&] { return io::read_recipe(file); });
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
