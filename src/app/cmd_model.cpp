// hotgauge model build|info: the PPF model file (docs/model-file.md). `build` makes the model
// from a recipe's geometry, a mesh or a reference scan and saves it; `info` prints a saved one.
#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <system_error>

#include "commands.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/match/model.hpp"
#include "hotgauge/model/model_io.hpp"
#include "hotgauge/pipeline/pipeline.hpp"

namespace hotgauge::app {
namespace {

struct ModelArgs {
    std::string recipe = HOTGAUGE_CONFIG_DIR "/parts/hub-a.yaml";
    std::string mesh, scan, out, file;
    std::optional<double> sampling_mm;  // default: the recipe's matching.sampling_mm
};

int run_build(const ModelArgs& a) {
    auto recipe = io::read_recipe(a.recipe);
    if (!recipe) {
        spdlog::error("{}", recipe.error().message);
        return 1;
    }
    const auto t0 = std::chrono::steady_clock::now();
    // From --mesh, --scan, the recipe's mesh_file, or else its sections.
    auto model = pipeline::part_model(
        *recipe, {.mesh = a.mesh, .scan = a.scan, .sampling_mm = a.sampling_mm});
    const double build_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!model) {
        spdlog::error("{}", model.error().message);
        return 1;
    }
    if (auto w = model::write_model(*model, a.out); !w) {
        spdlog::error("{}", w.error().message);
        return 1;
    }
    std::error_code ec;
    const auto bytes = std::filesystem::file_size(a.out, ec);
    std::cout << "model " << model->name << " (" << model->source << "): " << model->points.size()
              << " samples, " << model->refs.size() << " references, " << model->entries.size()
              << " table entries, " << std::fixed << std::setprecision(2)
              << (ec ? 0.0 : static_cast<double>(bytes) / 1e6) << " MB, built in "
              << std::setprecision(3) << build_s << " s -> " << a.out << '\n';
    return 0;
}

int run_info(const ModelArgs& a) {
    auto model = model::read_model(a.file);
    if (!model) {
        spdlog::error("{}", model.error().message);
        return 1;
    }
    const match::Model& m = *model;
    std::error_code ec;
    const auto bytes = std::filesystem::file_size(a.file, ec);
    std::cout << "file            " << a.file << " (" << (ec ? 0 : bytes) << " bytes)\n"
              << "format version  " << model::kModelFormatVersion << '\n'
              << "name            " << m.name << '\n'
              << "source          " << m.source << '\n'
              << "axisymmetric    " << (m.axisymmetric ? "yes" : "no") << '\n'
              << "diameter_mm     " << m.diameter_mm << '\n'
              << "step_mm         " << m.step_mm << '\n'
              << "config          sampling_mm " << m.config.sampling_mm << ", distance_step_mm "
              << m.config.distance_step_mm << ", angle_bins " << m.config.angle_bins
              << ", alpha_bins " << m.config.alpha_bins << '\n'
              << "samples         " << m.points.size() << '\n'
              << "references      " << m.refs.size() << '\n'
              << "profile         " << m.profile.size() << " segments\n"
              << "dense samples   " << m.dense_points.size() << '\n'
              << "table           " << m.n_keys() << " keys, " << m.entries.size() << " entries\n";
    return 0;
}

}  // namespace

Command add_model(CLI::App& app) {
    auto a = std::make_shared<ModelArgs>();
    auto* s = app.add_subcommand("model", "build or inspect a PPF model file (docs/model-file.md)");
    s->require_subcommand(1);
    auto* build = s->add_subcommand("build", "build the model of a part and save it");
    build->add_option("--recipe", a->recipe, "part recipe")->capture_default_str();
    auto* mesh = build->add_option("--mesh", a->mesh, "surface mesh, part frame, mm (.ply, .stl)");
    auto* scan =
        build->add_option("--scan", a->scan, "reference scan, part frame, mm (.ply, .pcd)");
    mesh->excludes(scan);
    build
        ->add_option("--sampling-mm", a->sampling_mm,
                     "voting sample distance, mm (default: the recipe's matching.sampling_mm)")
        ->check(CLI::PositiveNumber);
    build->add_option("--out,-o", a->out, "model file to write (.hgm)")->required();
    auto* info = s->add_subcommand("info", "print what a model file holds");
    info->add_option("file", a->file, "model file (.hgm)")->required();
    return [a, build] { return build->parsed() ? run_build(*a) : run_info(*a); };
}

}  // namespace hotgauge::app
