#pragma once
// The one pipeline function the offline tool and the daemon share: recording in, part result out
// (docs/architecture.md). Stages: [compensation] → pose → measurement → thermal scaling.
#include <Eigen/Geometry>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hotgauge/compensate/compensate.hpp"
#include "hotgauge/core/part.hpp"
#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/match/match.hpp"
#include "hotgauge/measure/features.hpp"

namespace hotgauge::pipeline {

struct PipelineOptions {
    // A known pose (--part-pose, --pose truth) skips matching; otherwise the part is found in
    // the scans with `model` (a loaded model file), or a model built from the recipe.
    std::optional<Eigen::Isometry3d> T_world_part;
    std::string pose_source;  // where a known pose came from, for the report
    const match::Model* model = nullptr;
    match::MatchConfig match;  // min_score and sampling come from the recipe
    bool compensate = true;    // vibration compensation (--no-compensation)
    compensate::CompensationConfig compensation;
    measure::MeasureConfig measure;
    // The threads are match.threads and measure.threads (both 0, one per core, by default;
    // --threads sets both); the result is the same to the bit on any number of them.
};

// What compensation did on one face (its per-profile u is PartResult::displacement_mm).
struct FaceCompensationSummary {
    std::string face;
    bool applied = false, degraded = false;
    std::vector<std::string> reasons;
    std::int64_t n_degraded = 0;
    double peak_mm = 0, rms_mm = 0, rate_hz = 0;
    std::vector<core::UntrustedProfiles> untrusted;  // the profiles it could not follow
    // Its own error (compensate::FaceCompensation): the accelerometer's noise density read off
    // the record, and the σ of the displacement error it leaves, per world axis; 0: not known.
    std::array<double, 3> accel_noise_ug{0, 0, 0}, drift_sigma_mm{0, 0, 0};
    // The profiles whose u_z the support plate gave, and its median's standard error.
    std::int64_t plate_profiles = 0;
    double plate_sigma_mm = 0;
};

// What was acquired on one face: enough for an engineer to judge the data before the numbers.
struct FaceSummary {
    std::string name;
    std::int64_t profiles = 0, width = 0, points = 0;
    double nan_fraction = 0;
    double scan_s = 0;
    std::int64_t accel_samples = 0;
    double accel_rate_hz = 0;
    std::optional<double> margin_before_s, margin_after_s;  // accelerometer cover of the scan
};
FaceSummary summarize(const core::FaceScan& face);

struct PartResult {
    std::string part_id, recipe, captured_at;
    std::string pose_source;  // "match", or where a given pose came from; "" = no pose
    std::optional<match::MatchResult> match;  // when matching ran
    std::vector<FaceSummary> faces;
    bool compensated = false;  // compensation was requested and ran
    std::vector<FaceCompensationSummary> compensation;
    // A feature is degraded (measured only with untrusted profiles), or the cell found the data
    // wanting (daemon: part temperature unknown): one reason each.
    bool degraded = false;
    std::vector<std::string> degraded_reasons;
    measure::PartMeasurement measurement;
    // What the measurement saw the scans with, for pictures of the part (report::part_report_html):
    // the pose (none: nothing measured) and each face's displacement per profile (a face absent:
    // not compensated).
    std::optional<Eigen::Isometry3d> T_world_part;
    core::FaceDisplacements displacement_mm;
    std::vector<std::string> warnings;                     // reader findings, degraded conditions
    std::vector<std::pair<std::string, double>> stage_ms;  // wall time per stage
};

PartResult run(const core::Recording& rec, const core::Recipe& recipe,
               const PipelineOptions& options);

// Where a part's PPF model comes from (docs/model-file.md), first match wins: a saved model
// file; a mesh (PLY/STL) or a reference scan (PLY/PCD); the recipe's geometry.mesh_file; the
// recipe's sections.
struct ModelSource {
    // Initialized, so that a caller names only the source it has ({.model_file = f}).
    std::filesystem::path model_file{}, mesh{}, scan{};
    std::optional<double> sampling_mm{};  // default: the recipe's matching.sampling_mm
};

// The part's PPF model, the one way the tool (measure, model build) and the daemon get it: a
// model file is read and checked to be the recipe's part; otherwise the model is built. The
// error names the file or the recipe.
core::Result<match::Model> part_model(const core::Recipe& recipe, const ModelSource& source = {});

// run() in steps, so that a cell has its answer soon after the last profile (docs/architecture.md
// "Latency"). The constructor and measure_all_but_last() need of the last face's accelerometer
// record only what precedes its last profile: the constructor compensates the other faces and
// finds the pose with the last face's record up to its last profile (measured to change no
// feature by more than 2.1 µm, docs/benchmarks.md "Daemon latency"); measure_all_but_last()
// measures every feature the other faces complete. finish() compensates the last face with its
// whole record and measures the rest. run() is the constructor and finish(); the numbers do not
// depend on whether measure_all_but_last() ran. `rec` and `recipe` must outlive the run; between
// the calls only the last face's accelerometer record may change (grow).
class PartRun {
  public:
    PartRun(const core::Recording& rec, const core::Recipe& recipe, const PipelineOptions& options);
    ~PartRun();
    PartRun(const PartRun&) = delete;
    PartRun& operator=(const PartRun&) = delete;
    void measure_all_but_last();
    PartResult finish();  // once

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// The stable machine interface (docs/measure-output.md): one JSON object.
std::string to_json(const PartResult& result);
// The human table, laid out like the paper's Table 2.
std::string to_table(const PartResult& result);

}  // namespace hotgauge::pipeline
