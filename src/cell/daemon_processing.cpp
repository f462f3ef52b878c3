// The daemon's processing thread (daemon_state.hpp): each captured part measured, stored and
// published, in that order (a result the PLC can acknowledge is already on disk).
#include <malloc.h>
#include <spdlog/spdlog.h>

#include <sstream>

#include "daemon_state.hpp"
#include "hotgauge/cell/journal.hpp"
#include "hotgauge/core/clock.hpp"
#include "hotgauge/measure/features.hpp"
#include "hotgauge/pipeline/verify.hpp"
#include "plc_result.hpp"

namespace hotgauge::cell {

void Daemon::Impl::prepare_results(const std::shared_ptr<const Setup>& s) {
    if (proc_setup && proc_setup->config.results.dir == s->config.results.dir &&
        proc_setup->config.archive.dir == s->config.archive.dir &&
        proc_setup->config.archive.quota_bytes == s->config.archive.quota_bytes &&
        proc_setup->config.archive.every_nth_ok == s->config.archive.every_nth_ok &&
        proc_setup->config.quality.drift_baseline == s->config.quality.drift_baseline &&
        proc_setup->config.quality.lot_report == s->config.quality.lot_report &&
        proc_setup->config.quality.lot_report_every_s == s->config.quality.lot_report_every_s &&
        log) {
        proc_setup = s;
        return;
    }
    proc_setup = s;
    log.reset();
    archive.reset();
    auto l = results::ResultsLog::open(s->config.results);
    if (!l) {
        log_error = l.error().message;
    } else {
        log.emplace(std::move(*l));
        log_error.clear();
    }
    if (auto a = results::RawArchive::open(s->config.archive); a) {
        archive.emplace(std::move(*a));
        archive->complete(
            results::last_result_lines(s->config.results.dir, results::ResultsLog::kRecoverLines));
    } else
        spdlog::error("raw archive: {}", a.error().message);
    quality.emplace(s->config.results.dir, s->config.quality);
    quality->load(core::realtime_ns());
}

namespace {

// glibc keeps what a part freed (its profiles, clouds and archive buffers: hundreds of MB) for
// reuse, so the idle RSS swung 60–260 MB from part to part in the soak, which would hide a
// leak. Given back after each part. (A sample taken right after DONE can still catch the
// archive of a degraded part being written: the 1 000-part soak's idle medians were 87–105 MB.)
void release_freed_memory() {
#if defined(__GLIBC__)
    malloc_trim(0);
#endif
}

}  // namespace

void Daemon::Impl::processing_loop() {
    while (!workers_stop || captured.size() > 0) {
        proc_beat = steady_ns();
        auto c = captured.pop(kLoopPeriod);
        if (!c) continue;
        process(std::move(*c));
        proc_beat = steady_ns();
        --in_flight;
        release_freed_memory();
    }
}

// The pipeline in its two steps (pipeline::PartRun): every face but the last while the last
// face's accelerometer margin runs, then the last face.
pipeline::PartResult Daemon::Impl::measure_captured(Captured& c) const {
    const Job& job = c.job;
    pipeline::PartResult r;
    if (c.fault) {
        r.part_id = c.rec.part_id;
        r.recipe = c.rec.recipe;
        r.captured_at = c.rec.captured_at;
        r.measurement = measure::unmeasured(*job.recipe, c.rec, c.failure);
        r.measurement.temperature_c = c.rec.temperature_c;
        r.warnings.push_back(c.failure);
        return r;
    }
    const PipelineSettings& ps = job.setup->config.pipeline;
    pipeline::PipelineOptions opt;
    opt.model = job.setup->models.at(job.trigger.recipe_slot).get();
    // No accelerometer configured (source: none): nothing to compensate with, as with
    // `hotgauge measure --no-compensation` (a warning, not every feature degraded).
    opt.compensate = accel != nullptr && ps.compensate;
    opt.compensation.highpass_hz = ps.highpass_hz;
    opt.match.threads = ps.threads;
    opt.measure.threads = ps.threads;
    if (accel) refresh_last_face(c, c.last_profile_ns + ring->period_ns(), 0.2);
    pipeline::PartRun run(c.rec, *job.recipe, opt);
    run.measure_all_but_last();
    if (accel) {
        refresh_last_face(c, c.last_profile_ns + static_cast<std::int64_t>(c.margin_s * 1e9),
                          0.5 + c.margin_s);
        c.accel_wait_ms = ms_between(c.scanned, Clock::now());
    }
    const auto t0 = Clock::now();
    r = run.finish();
    if (!c.left_out.empty()) {  // the pose was found without them: nothing sorts the part
        std::string faces;
        for (const auto& f : c.left_out) faces += (faces.empty() ? "" : ", ") + f;
        measure::degrade_measured(r.measurement, "the pose was found without face " + faces +
                                                     " (its scans lost their start)");
    }
    c.after_margin_ms = ms_between(t0, Clock::now());
    if (!accel) r.warnings.push_back("no accelerometer configured: vibration not compensated");
    if (accel && !ps.compensate)
        r.warnings.push_back("pipeline.compensation is false: vibration not compensated");
    for (const auto& why : c.degraded) {
        r.degraded = true;
        r.degraded_reasons.push_back(why);
    }
    if (c.accel_wait_ms > 0) r.stage_ms.emplace(r.stage_ms.begin(), "accel_wait", c.accel_wait_ms);
    return r;
}

// What the PLC is shown for a measured part: values, verdicts, reasons, the drift watch's state.
plc::PartResult Daemon::Impl::shown_to_plc(const Captured& c,
                                           const results::ResultEntry& entry) const {
    const Job& job = c.job;
    plc::PartResult shown = to_plc(*entry.result, entry.verification);
    set_drift(shown, entry.drift);
    shown.sequence = job.sequence;
    shown.time_ns = entry.time_ns;
    if (auto rev = job.setup->recipe_revision.find(job.trigger.recipe_slot);
        rev != job.setup->recipe_revision.end())
        shown.recipe_revision = rev->second;
    if (!c.left_out.empty()) shown.reasons |= plc::reason::kFaceMissing;
    if (!accel || !job.setup->config.pipeline.compensate)
        shown.reasons |= plc::reason::kNotCompensated;
    return shown;
}

std::string Daemon::Impl::publish(const Captured& c, const results::ResultEntry& entry,
                                  const core::Result<void>& stored, const plc::PartResult& shown,
                                  bool& problem) {
    const Job& job = c.job;
    const pipeline::PartResult& r = *entry.result;
    const pipeline::Verification* check = entry.verification;
    problem = true;
    if (abandoned == job.sequence) {
        // The PLC reset this cycle and has moved on: neither a result nor a fault of it may
        // reach the registers now.
        return (c.fault ? std::string("NOT_MEASURED (") + c.failure + ")"
                        : verdict_text(r, check)) +
               ", not published: the PLC reset the cycle";
    }
    if (!stored) {
        server->fault(code(plc::ErrorCode::kNotStored));
        return "FAULT 206 (result not stored: " + stored.error().message + ")";
    }
    if (c.fault) {
        server->fault(c.fault);
        return "FAULT " + std::to_string(c.fault) + " (" +
               plc::to_string(static_cast<plc::ErrorCode>(c.fault)) + "): " + c.failure;
    }
    if (auto ok = server->finish(job.trigger.trigger_id, shown); !ok)
        return verdict_text(r, check) + ", not published: " + ok.error().message;
    problem = r.measurement.verdict != measure::Verdict::kOk || r.degraded;
    {
        std::lock_guard lock(stats_mutex);
        cycle_times.add(Clock::now() - job.triggered);
    }
    return verdict_text(r, check);
}

PartMetrics Daemon::Impl::part_metrics(const Captured& c, const pipeline::PartResult& r,
                                       bool stored) const {
    PartMetrics m;
    if (stored) m.verdict = measure::to_string(r.measurement.verdict);
    m.fault = !stored ? code(plc::ErrorCode::kNotStored) : c.fault;
    if (c.scanned != Clock::time_point{})
        m.scan_s = std::chrono::duration<double>(c.scanned - c.job.triggered).count();
    m.cycle_s = std::chrono::duration<double>(Clock::now() - c.job.triggered).count();
    m.stage_ms = r.stage_ms;
    return m;
}

// A part through processing: measured (with a master's check), stored (the commit), then
// published (registers, archive, journal, pages). Nothing is shown before it is on disk.
void Daemon::Impl::process(Captured c) {
    prepare_results(c.job.setup);
    Measured m = measure_part(c);
    const Stored s = store_part(c, m);
    publish_part(c, m, s);
}

// The pipeline and, for a master part, its check, whose verdict is the part's
// (docs/verification.md).
Daemon::Impl::Measured Daemon::Impl::measure_part(Captured& c) const {
    const Job& job = c.job;
    Measured m;
    if (const auto it = job.setup->masters.find(job.trigger.recipe_slot);
        it != job.setup->masters.end())
        m.master = &it->second;
    if (m.master && !c.rec.temperature_c) {  // a cold master: the pyrometer reads nothing
        c.rec.temperature_c = m.master->temperature_c;
        std::erase_if(c.degraded, [](const std::string& why) {
            return why.rfind("part temperature unknown", 0) == 0;
        });
    }
    m.r = measure_captured(c);
    const auto t_measured = Clock::now();
    if (m.master && !c.fault) {
        if (auto v = pipeline::verify(m.r, *m.master)) {
            m.verification = std::move(*v);
            m.r.measurement.verdict = m.verification->passed         ? measure::Verdict::kOk
                                      : m.verification->inconclusive ? measure::Verdict::kDegraded
                                                                     : measure::Verdict::kNok;
        } else {
            m.r.warnings.push_back("master check: " + v.error().message);
            m.r.measurement.verdict = measure::Verdict::kNotMeasured;
        }
    }
    // The pipeline's work after the margin: the last face's share and the master check (the
    // rest overlapped the margin).
    m.checked = Clock::now();
    m.pipeline_ms = c.after_margin_ms + ms_between(t_measured, m.checked);
    return m;
}

// The commit (docs/results.md "One commit per part"): the results line, with what the registers
// will show and where the raw recording will go, appended before the PLC is shown anything. The
// raw recording is written after the registers (it is large, and the PLC is waiting); a failure
// to write it is logged.
Daemon::Impl::Stored Daemon::Impl::store_part(const Captured& c, const Measured& m) {
    const Job& job = c.job;
    Stored s;
    results::ResultEntry& entry = s.entry;
    entry.time_ns = core::realtime_ns();
    entry.sequence = job.sequence;
    entry.result = &m.r;
    entry.verification = m.verification ? &*m.verification : nullptr;
    entry.software_version = HOTGAUGE_VERSION;
    entry.config_hash = job.setup->config.hash;
    entry.die_id = job.trigger.die_id;
    entry.remeasure_of = job.remeasure_of;
    if (auto h = job.setup->result_hash.find(job.trigger.recipe_slot);
        h != job.setup->result_hash.end())
        entry.result_hash = h->second;
    if (quality && !m.master && !c.fault) entry.drift = quality->observe(entry.die_id, m.r);
    s.shown = shown_to_plc(c, entry);
    entry.plc = plc_json(s.shown, c.fault);  // kept in the commit, to be shown again after a crash
    s.archiving = !c.fault && archive && archive->wants(m.r, job.sequence);
    if (s.archiving)
        entry.archived_as = archive->folder(c.rec.part_id, job.sequence, entry.time_ns).string();
    s.stored = log ? log->append(entry) : core::Result<void>(core::make_error(log_error));
    s.store_ms = ms_between(m.checked, Clock::now());
    {
        std::lock_guard lock(stats_mutex);
        store_error = s.stored ? "" : s.stored.error().message;
    }
    if (s.stored) committed_seq = job.sequence;
    if (!s.stored) {
        spdlog::error("seq {}: results NOT stored: {}; the result is only in this log: {}",
                      job.sequence, s.stored.error().message, pipeline::to_json(m.r));
        std::lock_guard lock(stats_mutex);  // triggered again, it is measured again, said so
        if (job.trigger.part_id != 0)
            unfinished = Unfinished{job.sequence, job.trigger.part_id, job.trigger.recipe_slot, {}};
    }
    return s;
}

// Registers last: a result the PLC can acknowledge is already on disk. Then what follows from
// the commit (the CSV row, the raw archive), the stats, the journal and the pages.
void Daemon::Impl::publish_part(Captured& c, const Measured& m, const Stored& s) {
    const Job& job = c.job;
    const bool stored = static_cast<bool>(s.stored);
    bool problem = true;
    const std::string outcome = publish(c, s.entry, s.stored, s.shown, problem);
    const std::int64_t published = core::realtime_ns();
    if (stored) log->sync_csv();  // off the PLC's wait: the row derived from the commit
    if (s.archiving && stored) {  // the archive follows from the commit
        if (auto where = archive->store(c.rec, job.sequence, s.entry.time_ns); !where) {
            spdlog::error("seq {}: raw archive: {} (the results line names {})", job.sequence,
                          where.error().message, *s.entry.archived_as);
            archive->not_archived(log->last_line(), "writing it failed: " + where.error().message);
        }
    }
    {
        std::lock_guard lock(stats_mutex);
        stats.last = PartTiming{job.sequence,    c.last_profile_ns, published,
                                c.accel_wait_ms, m.pipeline_ms,     s.store_ms};
        ++(c.fault || !stored ? stats.failed : stats.measured);
    }
    const std::string msg = part_message(c, m, s, outcome, published);
    log_part({job.sequence, m.r.part_id, m.r.recipe,
              verdict_field(c.fault != 0 || !stored,
                            to_plc(m.r, m.verification ? &*m.verification : nullptr).overall),
              msg, problem});
    // Last: the stats and the log above are the part's outcome, the pages can wait.
    PartNews news{stored ? log->last_line() : results::jsonl_line(s.entry),
                  outcome,
                  msg,
                  problem,
                  web ? &c.rec : nullptr,
                  {},
                  std::nullopt};
    if (stored) news.files = {log->last_csv(), log->last_jsonl()};
    if (s.archiving && stored) news.archived = fs::path(*s.entry.archived_as);
    if (quality && stored) quality->stored(news.jsonl_line, s.entry.time_ns);
    if (stored) plant->result(news.jsonl_line, job.sequence);  // the plant gets what committed
    plant->part(part_metrics(c, m.r, stored));
    board->part(news);
}

// The part's line in the journal: outcome, master check, where the time went, reasons, files.
std::string Daemon::Impl::part_message(const Captured& c, const Measured& m, const Stored& s,
                                       const std::string& outcome,
                                       std::int64_t published_ns) const {
    const Job& job = c.job;
    const bool stored = static_cast<bool>(s.stored);
    std::ostringstream msg;
    msg << "part " << m.r.part_id << " seq " << job.sequence << " recipe " << m.r.recipe << ": "
        << outcome;
    if (m.master)
        msg << "; master " << m.master->master << " check "
            << (m.verification ? (m.verification->passed ? "passed" : "FAILED") : "not made");
    if (c.last_profile_ns)
        msg << "; " << (published_ns - c.last_profile_ns) / 1'000'000
            << " ms after the last profile (accelerometer margin " << std::lround(c.accel_wait_ms)
            << " ms, then pipeline " << std::lround(m.pipeline_ms) << " ms, files "
            << std::lround(s.store_ms) << " ms)";
    for (const auto& why : m.r.degraded_reasons) msg << "; degraded: " << why;
    if (stored && log->csv_error().empty()) msg << "; " << log->last_csv().string();
    if (stored && !log->csv_error().empty())
        msg << "; " << log->last_jsonl().string() << " (its CSV row is owed: " << log->csv_error()
            << ")";
    return msg.str();
}

}  // namespace hotgauge::cell
