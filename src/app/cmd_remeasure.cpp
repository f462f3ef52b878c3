// hotgauge remeasure: the archived parts of a results folder measured again (a new recipe, a new
// calibration) through the one pipeline, in parallel over parts, and compared with what the
// daemon said of them (docs/results.md "Re-measuring the archive").
#include <malloc.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <thread>

#include "commands.hpp"
#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/core/clock.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/io/recording_io.hpp"
#include "hotgauge/report/remeasure_report.hpp"
#include "hotgauge/results/compare.hpp"
#include "hotgauge/results/read_back.hpp"
#include "hotgauge/results/results_log.hpp"
#include "progress.hpp"

namespace hotgauge::app {
namespace {

namespace fs = std::filesystem;

struct RemeasureArgs {
    std::string results_dir, out;
    std::string from, to;  // local time prefixes (results::TimeRange)
    std::string recipe, calibration, model;
    bool no_compensation = false;
    double highpass_hz = 0.0;
    int jobs = 0;  // parts at once; 0: one per core
};

// What every part is measured with: the recipes (by name) and their models, the calibration.
struct Setup {
    std::map<std::string, core::Recipe> recipes;
    std::map<std::string, std::unique_ptr<match::Model>> models;
    std::optional<calib::Calibration> calibration;
    pipeline::PipelineOptions options;  // without its model
};

// One archived part to measure again.
struct Job {
    results::PartRecord before;
    fs::path recording;
    std::optional<pipeline::PartResult> result;
    std::string failure;  // why it could not be measured again
};

// Ctrl-C (SIGINT) and SIGTERM: no new part is started; the parts being measured finish and are
// written with everything before them. A second one ends the process (SA_RESETHAND). A results
// line that cannot be written stops the run too (g_write_failed), as an error.
std::atomic<bool> g_interrupted{false}, g_write_failed{false};
static_assert(std::atomic<bool>::is_always_lock_free, "set from a signal handler");
extern "C" void on_stop_signal(int) { g_interrupted = true; }
bool stopping() { return g_interrupted || g_write_failed; }

class StopSignals {
  public:
    StopSignals() {
        struct sigaction sa {};
        sa.sa_handler = on_stop_signal;
        sa.sa_flags = SA_RESETHAND;
        sigemptyset(&sa.sa_mask);
        sigaction(SIGINT, &sa, &old_int_);
        sigaction(SIGTERM, &sa, &old_term_);
    }
    ~StopSignals() {
        sigaction(SIGINT, &old_int_, nullptr);
        sigaction(SIGTERM, &old_term_, nullptr);
    }
    StopSignals(const StopSignals&) = delete;
    StopSignals& operator=(const StopSignals&) = delete;

  private:
    struct sigaction old_int_ {
    }, old_term_{};
};

// The recipe a part is measured with: --recipe, whose part must be the archived part's, or the
// shipped config/parts/<recipe>.yaml, as `hotgauge measure` takes it.
core::Result<const core::Recipe*> recipe_for(const RemeasureArgs& a, const std::string& name,
                                             Setup& s) {
    if (auto it = s.recipes.find(name); it != s.recipes.end()) return &it->second;
    const std::string path = a.recipe.empty() ? shipped_recipe(name) : a.recipe;
    auto recipe = io::read_recipe(path);
    if (!recipe) return recipe.error();
    if (recipe->name != name)
        return core::make_error(path + " is the recipe of part '" + recipe->name +
                                "'; the archived parts are '" + name + "'");
    auto model = pipeline::part_model(*recipe, {.model_file = a.model});
    if (!model) return model.error();
    s.models[name] = std::make_unique<match::Model>(std::move(*model));
    return &(s.recipes[name] = std::move(*recipe));
}

// The archived parts in the range, each with its recording; the parts that have none (an OK part
// the archive did not keep, a folder deleted for the quota) are listed with why.
core::Result<std::vector<Job>> archived_parts(const RemeasureArgs& a,
                                              std::vector<results::NotRemeasured>& left) {
    auto read = results::read_parts(a.results_dir, {a.from, a.to}, true);
    if (!read) return read.error();
    for (const auto& bad : read->skipped) spdlog::warn("{}", bad);
    std::vector<Job> jobs;
    for (auto& p : read->parts) {
        if (p.master_check) continue;  // a master's check is checked again by `hotgauge verify`
        auto folder = results::archived_folder(a.results_dir, p, a.results_dir);
        if (!folder) {
            left.push_back({p.sequence, p.part_id, folder.error().message});
            continue;
        }
        jobs.push_back({std::move(p), *folder, std::nullopt, {}});
    }
    return jobs;
}

// Every recipe the jobs need read once, with its model. A part whose recipe cannot be had (not
// the one given, a shipped recipe that cannot be read) is left out with why; when no part is
// left the run is refused, naming every recipe and why.
core::Result<void> prepare(const RemeasureArgs& a, std::vector<Job>& jobs, Setup& s,
                           std::vector<results::NotRemeasured>& left) {
    std::vector<Job> kept;
    std::map<std::string, std::string> refused;  // recipe name -> why
    for (auto& job : jobs) {
        const std::string& name = job.before.recipe;
        if (!refused.contains(name)) {
            auto recipe = recipe_for(a, name, s);
            if (recipe) {
                kept.push_back(std::move(job));
                continue;
            }
            refused[name] = recipe.error().message;
        }
        left.push_back({job.before.sequence, job.before.part_id, refused[name]});
    }
    if (kept.empty() && !refused.empty()) {
        std::string why;
        for (const auto& [name, what] : refused) why += (why.empty() ? "" : "; ") + what;
        return core::make_error(why);
    }
    jobs = std::move(kept);
    if (!a.calibration.empty()) {
        auto cal = calib::read_calibration(a.calibration);
        if (!cal) return cal.error();
        s.calibration = std::move(*cal);
    }
    s.options.compensate = !a.no_compensation;
    if (a.highpass_hz > 0) s.options.compensation.highpass_hz = a.highpass_hz;
    s.options.match.threads = 1;  // parallel over parts; the numbers are the same on any number
    s.options.measure.threads = 1;
    return {};
}

// One part through the pipeline, as `hotgauge measure` would measure its recording.
void measure_one(const RemeasureArgs& a, const Setup& s, Job& job) {
    auto rec = io::read_recording(job.recording);
    if (!rec) {
        job.failure = rec.error().message;
        return;
    }
    if (s.calibration) {
        if (auto ok = calib::apply_geometry(*s.calibration, a.calibration, *rec); !ok) {
            job.failure = ok.error().message;
            return;
        }
    }
    pipeline::PipelineOptions options = s.options;
    options.model = s.models.at(job.before.recipe).get();
    job.result = pipeline::run(*rec, s.recipes.at(job.before.recipe), options);
}

// The parts measured on `workers` threads, each part on one; `commit(n)` is called on this
// thread whenever the first n parts are done, in order. After a stop signal no part is started;
// the ones being measured finish, and the last commit covers every part that was started.
void measure_all(const RemeasureArgs& a, const Setup& s, std::vector<Job>& jobs, int workers,
                 const std::function<void(std::size_t)>& commit) {
    std::atomic<std::size_t> next{0};
    std::atomic<int> running{workers};
    std::vector<std::uint8_t> done(jobs.size(), 0);
    std::mutex m;
    std::condition_variable cv;
    auto work = [&] {
        for (std::size_t i; !stopping() && (i = next++) < jobs.size();) {
            try {
                measure_one(a, s, jobs[i]);
            } catch (const std::exception& e) {  // a part that breaks the pipeline: not the run
                jobs[i].failure = std::string("the pipeline failed: ") + e.what();
            }
            std::lock_guard lock(m);
            done[i] = 1;
            cv.notify_one();
        }
        std::lock_guard lock(m);
        --running;
        cv.notify_one();
    };
    std::vector<std::thread> threads;
    for (int t = 0; t < workers; ++t) threads.emplace_back(work);
    std::size_t ready = 0;
    for (bool last = false; !last;) {
        std::unique_lock lock(m);
        cv.wait_for(lock, std::chrono::milliseconds(200));
        last = running == 0;
        while (ready < jobs.size() && done[ready]) ++ready;
        lock.unlock();
        commit(ready);
    }
    for (auto& t : threads) t.join();
}

// The part's new result in the daemon's format (results::ResultsLog: its sequence and time, so
// that it lands in the same day file), and read back as the comparison reads the daemon's.
core::Result<results::PartRecord> write_one(results::ResultsLog& log, const Job& job) {
    results::ResultEntry entry;
    entry.time_ns = job.before.time_ns;
    entry.sequence = job.before.sequence;
    entry.result = &*job.result;
    entry.software_version = HOTGAUGE_VERSION;
    entry.die_id = job.before.die;
    entry.archived_as = job.recording.string();
    if (auto ok = log.append(entry); !ok) return ok.error();
    return results::parse_result_line(log.last_line());
}

struct Outcome {
    std::vector<results::PartRecord> before, after;
    std::vector<results::NotRemeasured> left;
    std::size_t measured = 0;
};

// The jobs measured and written in order to OUT/results, with the progress on stderr.
core::Result<void> measure_and_write(const RemeasureArgs& a, const Setup& s, std::vector<Job>& jobs,
                                     Outcome& out) {
    auto log = results::ResultsLog::open({fs::path(a.out) / "results", false});
    if (!log) return log.error();
    const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    const int workers = static_cast<int>(
        std::min<std::size_t>(a.jobs > 0 ? a.jobs : cores, std::max<std::size_t>(jobs.size(), 1)));
    Progress progress(stderr, jobs.size(), "parts");
    std::size_t written = 0;
    std::string error;
    measure_all(a, s, jobs, workers, [&](std::size_t ready) {
        for (; written < ready && error.empty(); ++written) {
            Job& job = jobs[written];
            if (!job.result) {
                out.left.push_back({job.before.sequence, job.before.part_id, job.failure});
                continue;
            }
            auto after = write_one(*log, job);
            job.result.reset();  // its profiles and clouds are not needed any more
            if (!after) {        // the out folder takes no more: stop, keep what is written
                g_write_failed = true;
                error = after.error().message;
                out.left.push_back({job.before.sequence, job.before.part_id, error});
                continue;
            }
            out.before.push_back(job.before);
            out.after.push_back(std::move(*after));
            ++out.measured;
        }
        progress.update(written);
    });
    for (std::size_t i = written; i < jobs.size() && !error.empty(); ++i)
        out.left.push_back({jobs[i].before.sequence, jobs[i].before.part_id,
                            "not written: an earlier part's results line could not be"});
    progress.finish(written, g_interrupted && error.empty()
                                 ? "stopped: " + std::to_string(out.measured) + " of " +
                                       std::to_string(jobs.size()) + " parts measured again"
                                 : "");
    if (!error.empty()) return core::make_error(error);
    return {};
}

// The comparison on stdout, and as OUT/comparison.json and OUT/remeasure.html.
core::Result<void> report(const RemeasureArgs& a, const Outcome& out, std::size_t in_range,
                          double wall_s) {
    const results::Comparison c = results::compare_parts(out.before, out.after, out.left);
    std::fputs(results::comparison_table(c).c_str(), stdout);
    report::RemeasureInfo info;
    info.results_dir = a.results_dir;
    info.out_dir = a.out;
    info.recipe = a.recipe;
    info.calibration = a.calibration;
    info.parts_in_range = in_range;
    info.parts_measured = out.measured;
    info.wall_s = wall_s;
    info.stopped = g_interrupted && !g_write_failed;
    info.generated_at = results::local_iso8601(core::realtime_ns());
    for (const auto& [name, text] :
         {std::pair{"comparison.json", results::comparison_json(c)},
          std::pair{"remeasure.html", report::remeasure_html(c, info)}}) {
        const fs::path file = fs::path(a.out) / name;
        std::ofstream f(file);
        if (!(f << text << '\n'))
            return core::make_error(file.string() + ": cannot write the comparison");
    }
    return {};
}

// A part's buffers (profiles, clouds, frames: up to tens of MB each) are kept by the allocator for
// the next part instead of being mapped, zeroed by the kernel and unmapped for every part: on 40
// parts the system time fell from 2.0 s to 1.1 s (tests/bench/remeasure_bench.py).
void keep_freed_memory() {
#if defined(__GLIBC__)
    constexpr int kMmapThreshold = 32 << 20;  // glibc's largest: half its 64 MiB arena heaps
    constexpr int kTrimThreshold = 1 << 30;
    mallopt(M_MMAP_THRESHOLD, kMmapThreshold);
    mallopt(M_TRIM_THRESHOLD, kTrimThreshold);
#endif
}

// OUT/results must be a folder of its own: not the daemon's results folder, and without results
// of an earlier run (its lines would be read as this run's).
core::Result<void> check_out(const RemeasureArgs& a) {
    const fs::path results = fs::path(a.out) / "results";
    std::error_code ec;
    if (fs::exists(results, ec) && fs::equivalent(results, a.results_dir, ec))
        return core::make_error(results.string() + " is " + a.results_dir +
                                ", the results read: give --out another folder");
    for (fs::directory_iterator it(results, ec), end; !ec && it != end; it.increment(ec))
        if (it->path().extension() == ".jsonl")
            return core::make_error(results.string() + " holds results already (" +
                                    it->path().filename().string() +
                                    "): give --out an empty or new folder");
    return {};
}

int run(const RemeasureArgs& a) {
    g_interrupted = false;
    g_write_failed = false;
    if (auto ok = check_out(a); !ok) {
        spdlog::error("{}", ok.error().message);
        return 1;
    }
    keep_freed_memory();
    StopSignals signals;
    const auto t0 = std::chrono::steady_clock::now();
    Outcome out;
    auto jobs = archived_parts(a, out.left);
    Setup setup;
    auto ok = jobs ? prepare(a, *jobs, setup, out.left) : core::Result<void>(jobs.error());
    const std::size_t in_range = jobs ? jobs->size() + out.left.size() : 0;
    if (ok) ok = measure_and_write(a, setup, *jobs, out);
    if (!ok) {
        spdlog::error("{}", ok.error().message);
        if (out.measured == 0) return 1;
    }
    const double wall_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (auto r = report(a, out, in_range, wall_s); !r) {
        spdlog::error("{}", r.error().message);
        return 1;
    }
    spdlog::info("{} of {} parts measured again in {:.1f} s ({:.1f} parts/s); results in {}",
                 out.measured, in_range, wall_s,
                 static_cast<double>(out.measured) / std::max(wall_s, 1e-9),
                 (fs::path(a.out) / "results").string());
    if (!ok) return 1;
    if (g_interrupted) return 130;  // as a shell reports a job stopped by Ctrl-C
    return out.measured > 0 ? 0 : 1;
}

}  // namespace

Command add_remeasure(CLI::App& app) {
    auto a = std::make_shared<RemeasureArgs>();
    auto* s = app.add_subcommand(
        "remeasure",
        "measure the archived parts of a results folder again and compare with what the daemon "
        "said (docs/results.md \"Re-measuring the archive\")");
    s->add_option("results", a->results_dir, "the daemon's results folder (*.jsonl)")->required();
    s->add_option("--out", a->out, "folder for the new results and the comparison")->required();
    s->add_option("--from", a->from, "first part's local time prefix, e.g. 2026-12-04T06");
    s->add_option("--to", a->to, "last part's local time prefix, e.g. 2026-12-04T13");
    s->add_option("--recipe", a->recipe,
                  "recipe to measure with (default: config/parts/<the part's recipe>.yaml); "
                  "it must be the archived parts' part");
    s->add_option("--calibration", a->calibration,
                  "calibration.yaml: the cell's geometry replaces the recordings' face.yaml");
    s->add_option("--model", a->model, "PPF model file (default: built from the recipe)");
    s->add_flag("--no-compensation", a->no_compensation, "measure without vibration compensation");
    s->add_option("--highpass-hz", a->highpass_hz, "compensation high-pass corner, Hz");
    s->add_option("--jobs", a->jobs, "parts measured at once, 0: one per core")
        ->check(CLI::Range(0, 64))
        ->capture_default_str();
    return [a] { return run(*a); };
}

}  // namespace hotgauge::app
