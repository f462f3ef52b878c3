// hotgauge measure: the offline pipeline on a recording (pipeline::run, the daemon's function).
#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>

#include "commands.hpp"
#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/core/geometry.hpp"
#include "hotgauge/io/ply.hpp"
#include "hotgauge/io/pose_io.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/io/recording_io.hpp"
#include "hotgauge/model/model_io.hpp"
#include "hotgauge/pipeline/pipeline.hpp"

namespace hotgauge::app {
namespace {

namespace fs = std::filesystem;

struct MeasureArgs {
    MeasureJob job;
    std::string ply;
    bool json = false;
};

}  // namespace

std::optional<pipeline::PartResult> measure_job(const MeasureJob& a, core::Recording* rec_out,
                                                core::Recipe* recipe_out) {
    auto rec = io::read_recording(a.recording);
    if (!rec) {
        spdlog::error("{}", rec.error().message);
        return std::nullopt;
    }
    if (!rec->temperature_c && a.default_temperature_c) {
        spdlog::info("{}: no temperature recorded, taken as {} °C", a.recording,
                     *a.default_temperature_c);
        rec->temperature_c = a.default_temperature_c;
    }
    if (!a.calibration.empty()) {
        auto cal = calib::read_calibration(a.calibration);
        auto applied = cal ? calib::apply_geometry(*cal, a.calibration, *rec) : cal.error();
        if (!applied) {
            spdlog::error("{}", applied.error().message);
            return std::nullopt;
        }
        if (!cal->measured())
            spdlog::warn("{}: method {}: the faces' geometry is not measured", a.calibration,
                         cal->method);
    }
    const std::string recipe_path = a.recipe.empty() ? shipped_recipe(rec->recipe) : a.recipe;
    auto recipe = io::read_recipe(recipe_path);
    if (!recipe) {
        spdlog::error("{}", recipe.error().message);
        return std::nullopt;
    }
    pipeline::PipelineOptions opt;
    opt.compensate = !a.no_compensation;
    opt.compensation.clock_offset_s = a.clock_offset_ms * 1e-3;
    if (a.highpass_hz > 0) opt.compensation.highpass_hz = a.highpass_hz;
    opt.match.threads = a.threads;
    opt.measure.threads = a.threads;
    std::string pose_file = a.part_pose;
    if (a.pose == "truth") {
        if (!pose_file.empty()) {
            spdlog::error("give either --pose truth or --part-pose, not both");
            return std::nullopt;
        }
        pose_file = fs::path(a.recording).lexically_normal().string() + ".truth/part_pose.yaml";
        if (std::error_code ec; !fs::exists(pose_file, ec)) {
            spdlog::error("--pose truth: {} not found (only simulated recordings have a truth)",
                          pose_file);
            return std::nullopt;
        }
    }
    if (!pose_file.empty()) {
        auto pose = io::read_part_pose(pose_file);
        if (!pose) {
            spdlog::error("{}", pose.error().message);
            return std::nullopt;
        }
        opt.T_world_part = *pose;
        opt.pose_source = (a.pose == "truth" ? "truth " : "file ") + pose_file;
    }
    std::optional<match::Model> model;
    if (!a.model.empty()) {
        auto m = pipeline::part_model(*recipe, {.model_file = a.model});
        if (!m) {
            spdlog::error("{}", m.error().message);
            return std::nullopt;
        }
        model = std::move(*m);
        opt.model = &*model;
    }
    pipeline::PartResult result = pipeline::run(*rec, *recipe, opt);
    for (const auto& w : result.warnings) spdlog::warn("{}", w);
    if (rec_out) *rec_out = std::move(*rec);
    if (recipe_out) *recipe_out = std::move(*recipe);
    return result;
}

namespace {

int run(const MeasureArgs& a) {
    core::Recording rec;
    const auto result = measure_job(a.job, &rec);
    if (!result) return 1;
    if (a.json)
        std::printf("%s\n", pipeline::to_json(*result).c_str());
    else
        std::fputs(pipeline::to_table(*result).c_str(), stdout);

    if (!a.ply.empty()) {
        std::vector<Eigen::Vector3d> all;
        for (const auto& f : rec.faces) {
            auto cloud = core::world_cloud(f);
            all.insert(all.end(), cloud.points_mm.begin(), cloud.points_mm.end());
        }
        if (auto r = io::write_ply(a.ply, all); !r) {
            spdlog::error("{}", r.error().message);
            return 1;
        }
        spdlog::info("wrote {} world points (nominal, uncompensated) to {}", all.size(), a.ply);
    }
    return 0;
}

}  // namespace

void add_measure_job_options(CLI::App* s, MeasureJob& j) {
    s->add_option("recording", j.recording, "recording folder (hotgauge-recording/1)")->required();
    s->add_option("--recipe", j.recipe, "part recipe (default: config/parts/<recipe>.yaml)");
    s->add_option("--pose", j.pose,
                  "where the part pose comes from: match (find it in the scans) or truth "
                  "(REC.truth/part_pose.yaml, simulated recordings)")
        ->check(CLI::IsMember({"match", "truth"}))
        ->capture_default_str();
    s->add_option("--part-pose", j.part_pose, "part pose file (world_from_part): no matching");
    s->add_option("--model", j.model,
                  "PPF model file (hotgauge model build); default: built "
                  "from the recipe");
    s->add_flag("--no-compensation", j.no_compensation, "measure without vibration compensation");
    s->add_option("--clock-offset-ms", j.clock_offset_ms,
                  "accelerometer clock minus camera clock, ms")
        ->capture_default_str();
    s->add_option("--highpass-hz", j.highpass_hz,
                  "compensation high-pass corner, Hz (default 1.5)");
    s->add_option("--threads", j.threads,
                  "threads for matching and measurement, 0: one per core (the numbers are the "
                  "same on any number)")
        ->check(CLI::Range(0, 64))
        ->capture_default_str();
    s->add_option("--calibration", j.calibration,
                  "calibration.yaml: the cell's geometry replaces the recording's face.yaml "
                  "(docs/calibration.md)");
}

Command add_measure(CLI::App& app) {
    auto a = std::make_shared<MeasureArgs>();
    auto* s = app.add_subcommand("measure", "measure a recording (offline pipeline)");
    add_measure_job_options(s, a->job);
    s->add_flag("--json", a->json, "print one JSON object (docs/measure-output.md)");
    s->add_option("--ply", a->ply, "write the world cloud of all faces as binary PLY");
    return [a] { return run(*a); };
}

}  // namespace hotgauge::app
