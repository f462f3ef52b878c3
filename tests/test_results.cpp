// Results files (docs/results.md): content, spreadsheet-clean CSV (checked by Python's csv
// module), one JSON object per line, torn-line repair, full disk, recipes with other features.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>

#include <cstdlib>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "hotgauge/io/recording_io.hpp"
#include "hotgauge/results/archive.hpp"
#include "hotgauge/results/read_back.hpp"
#include "hotgauge/results/results_log.hpp"
#include "hotgauge/results/sequence.hpp"
#include "temp_dir.hpp"

namespace hotgauge {
namespace {

std::vector<std::string> lines(const std::filesystem::path& p) {
    std::ifstream in(p);
    std::vector<std::string> out;
    for (std::string l; std::getline(in, l);) out.push_back(l);
    return out;
}

pipeline::PartResult part(const std::string& id, int n_features, double base_mm) {
    pipeline::PartResult r;
    r.part_id = id;
    r.recipe = n_features == 3 ? "hub-a" : "hub-b";
    r.captured_at = "2026-11-22T07:00:00Z";
    r.pose_source = "match";
    r.measurement.temperature_c = 1012.5;
    r.measurement.growth = 1.0146;
    r.measurement.verdict = measure::Verdict::kOk;
    for (int i = 0; i < n_features; ++i) {
        measure::FeatureResult f;
        f.name = "Diameter " + std::to_string(i + 1);
        f.nominal_mm = base_mm + i;
        if (i == 1) {  // not measured: empty cells, the reason in the JSON
            f.verdict = measure::Verdict::kNotMeasured;
            f.reason = "edge not found, arc 12° < 30°";
        } else {
            f.verdict = measure::Verdict::kOk;
            f.cold_mm = base_mm + i + 0.0123;
            f.hot_mm = *f.cold_mm * 1.0146;
            f.deviation_mm = 0.0123;
        }
        r.measurement.features.push_back(f);
    }
    return r;
}

constexpr std::int64_t kNoon = 1'795'000'000'000'000'000;  // 2026-11-18, some time of day

TEST(ResultsLog, CsvOpensInASpreadsheetAndJsonLinesCarryEverything) {
    test::TempDir tmp;
    auto log = results::ResultsLog::open({tmp.path / "results", true});
    ASSERT_TRUE(log.ok()) << log.error().message;
    const auto a = part("A-1", 3, 60.0), b = part("B,\"2\"", 3, 60.0);  // a hostile part id
    ASSERT_TRUE(log->append({kNoon, 41, &a, "0.1.0", "cfg1234", std::nullopt}).ok());
    results::ResultEntry eb{kNoon + 1'000'000'000, 42, &b, "0.1.0", "cfg1234", "archive/x"};
    eb.die_id = 7;
    eb.remeasure_of = 17;  // measured again: its first measurement, number 17, never committed
    eb.drift = {
        {"Diameter 1", "DRIFT_UP"}, {"Diameter 2", "WATCHING"}, {"Diameter 3", "DRIFT_DOWN"}};
    ASSERT_TRUE(log->append(eb).ok());
    const auto csv = log->last_csv();
    EXPECT_EQ(csv.filename().string(), results::local_date(kNoon) + ".csv");
    const auto rows = lines(csv);
    ASSERT_EQ(rows.size(), 3u);
    EXPECT_EQ(
        rows[0].rfind("time,time_utc,sequence,part_id,recipe,temperature_c,verdict,degraded,drift,"
                      "remeasure_of,Diameter 1 value_mm,Diameter 1 deviation_mm,Diameter 1 verdict,"
                      "Diameter 1 nominal_mm,Diameter 1 lower_limit_mm,Diameter 1 upper_limit_mm,"
                      "Diameter 1 reason,",
                      0),
        0u)
        << rows[0];
    // An independent reader: every row has the header's columns, the quoted id survives.
    const std::string check =
        std::string(HOTGAUGE_PYTHON) +
        " -c \"import csv,sys; r=list(csv.reader(open(sys.argv[1]))); " +
        "assert all(len(x)==len(r[0]) for x in r), [len(x) for x in r]; " +
        "assert r[2][3]=='B,\\\"2\\\"', r[2][3]; " +
        "assert r[1][10]=='60.0123' and r[1][17]=='' and r[1][19]=='NOT_MEASURED', r[1]; " +
        "assert r[1][20]=='61.0000' and r[1][16]=='' and r[1][23].startswith('edge not found, "
        "arc 12'), r[1]; " +
        "assert r[1][1].endswith('Z') and r[1][1][:4]=='2026', r[1][1]; " +
        "assert r[1][8]=='' and r[2][8]=='Diameter 1 DRIFT_UP; Diameter 3 DRIFT_DOWN', r[2]; " +
        "assert r[1][9]=='' and r[2][9]=='17', r[2]\" " + csv.string();
    EXPECT_EQ(std::system(check.c_str()), 0) << check;

    const auto js = lines(log->last_jsonl());
    ASSERT_EQ(js.size(), 2u);
    const auto j = nlohmann::json::parse(js[1]);
    EXPECT_EQ(j["sequence"], 42);
    EXPECT_EQ(j["config_hash"], "cfg1234");
    EXPECT_EQ(j["archived_as"], "archive/x");
    EXPECT_EQ(j["die"], 7);
    EXPECT_EQ(j["drift"]["Diameter 2"], "WATCHING");
    EXPECT_EQ(j["remeasure_of"], 17);
    EXPECT_TRUE(nlohmann::json::parse(js[0])["remeasure_of"].is_null());
    EXPECT_EQ(j["part"]["part_id"], "B,\"2\"");
    EXPECT_EQ(j["part"]["features"][1]["reason"], "edge not found, arc 12° < 30°");
}

TEST(ResultsLog, ATornLastLineIsCutWhenTheFileIsOpenedAgain) {
    test::TempDir tmp;
    const auto dir = tmp.path / "results";
    const auto a = part("A-1", 3, 60.0);
    {
        auto log = results::ResultsLog::open({dir, true});
        ASSERT_TRUE(log.ok());
        ASSERT_TRUE(log->append({kNoon, 1, &a, "v", "h", std::nullopt}).ok());
    }
    const auto csv = dir / (results::local_date(kNoon) + ".csv");
    const auto jsonl = dir / (results::local_date(kNoon) + ".jsonl");
    {  // the power went in the middle of the next part's lines
        std::ofstream(csv, std::ios::app) << "2026-11-18T12:00:01,2,A-2,hub-a,10";
        std::ofstream(jsonl, std::ios::app) << "{\"time\":\"2026";
    }
    auto log = results::ResultsLog::open({dir, true});
    ASSERT_TRUE(log.ok());
    ASSERT_TRUE(log->append({kNoon + 2'000'000'000, 2, &a, "v", "h", std::nullopt}).ok());
    const auto rows = lines(csv);
    ASSERT_EQ(rows.size(), 3u);  // header, part 1, part 2: the torn row is gone
    EXPECT_NE(rows[2].find(",2,A-1,"), std::string::npos) << rows[2];
    for (const auto& l : lines(jsonl)) EXPECT_TRUE(nlohmann::json::accept(l)) << l;
    EXPECT_EQ(lines(jsonl).size(), 2u);
}

TEST(ResultsLog, ATornTailLongerThanOneReadBlockIsCutToo) {
    test::TempDir tmp;
    const auto dir = tmp.path / "results";
    const auto a = part("A-1", 3, 60.0);
    {
        auto log = results::ResultsLog::open({dir, false});
        ASSERT_TRUE(log.ok());
        for (int i = 1; i <= 100; ++i)
            ASSERT_TRUE(
                log->append({kNoon, static_cast<std::uint64_t>(i), &a, "v", "h", std::nullopt})
                    .ok());
    }
    const auto jsonl = dir / (results::local_date(kNoon) + ".jsonl");
    ASSERT_GT(std::filesystem::file_size(jsonl), 100'000u);  // the file spans several blocks
    std::ofstream(jsonl, std::ios::app) << std::string(150'000, 'x');  // no line break
    auto log = results::ResultsLog::open({dir, false});
    ASSERT_TRUE(log.ok());
    ASSERT_TRUE(log->append({kNoon, 101, &a, "v", "h", std::nullopt}).ok());
    const auto js = lines(jsonl);
    ASSERT_EQ(js.size(), 101u);
    for (const auto& l : js) EXPECT_TRUE(nlohmann::json::accept(l)) << l.substr(0, 80);
    EXPECT_EQ(lines(log->last_csv()).size(), 102u);  // the header was found again: not repeated
}

TEST(ResultsLog, AFullDiskIsAnErrorAndLeavesNoHalfLine) {
    test::TempDir tmp;
    const auto dir = tmp.path / "results";
    const auto a = part("A-1", 3, 60.0);
    auto log = results::ResultsLog::open({dir, true});
    ASSERT_TRUE(log.ok());
    ASSERT_TRUE(log->append({kNoon, 1, &a, "v", "h", std::nullopt}).ok());
    const auto jsonl = log->last_jsonl();
    const auto csv = log->last_csv();
    const auto size_json = std::filesystem::file_size(jsonl);
    const auto size_csv = std::filesystem::file_size(csv);
    // The disk "fills": no file may grow past 100 bytes more than the JSON file has now.
    signal(SIGXFSZ, SIG_IGN);  // the write fails with EFBIG instead of killing the process
    rlimit old{};
    getrlimit(RLIMIT_FSIZE, &old);
    rlimit small = old;
    small.rlim_cur = static_cast<rlim_t>(size_json + 100);
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
    auto full = log->append({kNoon + 1'000'000'000, 2, &a, "v", "h", std::nullopt});
    setrlimit(RLIMIT_FSIZE, &old);
    ASSERT_FALSE(full.ok());
    EXPECT_NE(full.error().message.find(jsonl.string()), std::string::npos) << full.error().message;
    EXPECT_EQ(std::filesystem::file_size(jsonl), size_json);  // nothing half written
    EXPECT_EQ(std::filesystem::file_size(csv), size_csv);
    // Space again: the next part is written, and everything before it is still there.
    ASSERT_TRUE(log->append({kNoon + 2'000'000'000, 2, &a, "v", "h", std::nullopt}).ok());
    EXPECT_EQ(lines(csv).size(), 3u);
    EXPECT_EQ(lines(jsonl).size(), 2u);
}

TEST(ResultsLog, ARecipeWithOtherFeaturesGetsItsOwnCsv) {
    test::TempDir tmp;
    auto log = results::ResultsLog::open({tmp.path / "results", false});
    ASSERT_TRUE(log.ok());
    const auto a = part("A-1", 3, 60.0), b = part("B-1", 5, 30.0);
    ASSERT_TRUE(log->append({kNoon, 1, &a, "v", "h", std::nullopt}).ok());
    ASSERT_TRUE(log->append({kNoon, 2, &b, "v", "h", std::nullopt}).ok());
    EXPECT_EQ(log->last_csv().filename().string(), results::local_date(kNoon) + ".hub-b.csv");
    EXPECT_EQ(lines(log->last_csv()).size(), 2u);
    EXPECT_EQ(lines(log->last_jsonl()).size(), 2u);  // one JSON file for the day
}

// A master check (docs/verification.md): its row in the day's verification CSV, with its own
// header, the part CSV untouched, and the verification in the part's JSON line.
TEST(ResultsLog, AMasterCheckIsAVerificationRow) {
    test::TempDir tmp;
    auto log = results::ResultsLog::open({tmp.path / "results", false});
    ASSERT_TRUE(log.ok());
    const auto a = part("A-1", 3, 60.0), m = part("M-0001", 3, 60.0);
    core::MasterCertificate cert;
    cert.master = "M-0001";
    cert.recipe = "hub-a";
    cert.certified_at = "2026-11-20";
    cert.features = {{"Diameter 1", 60.0123, 0.001, std::nullopt},
                     {"Diameter 3", 62.0523, 0.001, std::nullopt}};
    auto v = pipeline::verify(m, cert);
    ASSERT_TRUE(v.ok()) << v.error().message;
    EXPECT_FALSE(v->passed);  // Diameter 3 is 0.04 mm off
    ASSERT_TRUE(log->append({kNoon, 1, &a, "v", "h", std::nullopt}).ok());
    results::ResultEntry e{kNoon, 2, &m, "v", "h", std::nullopt};
    e.verification = &*v;
    ASSERT_TRUE(log->append(e).ok());
    EXPECT_EQ(log->last_csv().filename().string(),
              results::local_date(kNoon) + ".verification.csv");
    const auto rows = lines(log->last_csv());
    ASSERT_EQ(rows.size(), 2u);
    EXPECT_EQ(rows[0],
              "time,sequence,master,part_id,recipe,passed,Diameter 1 certified_mm,Diameter 1 "
              "deviation_mm,Diameter 1 passed,Diameter 3 certified_mm,Diameter 3 deviation_mm,"
              "Diameter 3 passed");
    EXPECT_NE(rows[1].find(",2,M-0001,M-0001,hub-a,no,60.0123,0.0000,yes,62.0523,-0.0400,no"),
              std::string::npos)
        << rows[1];
    EXPECT_EQ(lines(tmp.path / "results" / (results::local_date(kNoon) + ".csv")).size(), 2u);
    const auto json = lines(log->last_jsonl());
    ASSERT_EQ(json.size(), 2u);
    EXPECT_EQ(json[0].find("\"verification\""), std::string::npos);
    const auto j = nlohmann::json::parse(json[1]);
    EXPECT_EQ(j["verification"]["master"], "M-0001");
    EXPECT_EQ(j["verification"]["passed"], false);
    EXPECT_EQ(j["verification"]["features"][1]["reason"],
              "deviation -0.0400 mm outside ±0.0200 mm");
    // Another master certifying other features the same day: its own file, named safely.
    core::MasterCertificate other = cert;
    other.master = "M/0002";
    other.features.pop_back();
    auto v2 = pipeline::verify(m, other);
    ASSERT_TRUE(v2.ok());
    e.verification = &*v2;
    ASSERT_TRUE(log->append(e).ok());
    EXPECT_EQ(log->last_csv().filename().string(),
              results::local_date(kNoon) + ".verification.M_0002.csv");
    EXPECT_EQ(lines(log->last_csv()).size(), 2u);
}

// One commit per part (docs/results.md): a crash between a part's JSON line and its CSV row, or a
// power cut that lost unsynced CSV rows, is completed from the JSON lines at the next open, each
// row as the append would have written it, in order, once.
TEST(ResultsLog, CsvRowsACrashLeftOutAreWrittenFromTheJsonLinesAtOpen) {
    test::TempDir tmp;
    const auto dir = tmp.path / "results";
    const auto a = part("A-1", 3, 60.0), b = part("B-2", 4, 70.0), m = part("M-0001", 3, 60.0);
    core::MasterCertificate cert;
    cert.master = "M-0001";
    cert.recipe = "hub-a";
    cert.certified_at = "2026-11-20";
    cert.features = {{"Diameter 1", 60.0123, 0.001, std::nullopt}};
    auto v = pipeline::verify(m, cert);
    ASSERT_TRUE(v.ok()) << v.error().message;
    std::map<std::filesystem::path, std::vector<std::string>> whole;  // every CSV, all parts in
    {
        auto log = results::ResultsLog::open({dir, false});
        ASSERT_TRUE(log.ok());
        EXPECT_TRUE(log->completed_at_open().empty());
        for (std::uint64_t seq = 1; seq <= 6; ++seq) {
            // hub-a, hub-a, hub-b (its own file), a master check, hub-a, hub-b
            const auto* r = seq == 3 || seq == 6 ? &b : seq == 4 ? &m : &a;
            results::ResultEntry e{kNoon + static_cast<std::int64_t>(seq) * 1'000'000'000,
                                   seq,
                                   r,
                                   "v",
                                   "h",
                                   std::nullopt};
            if (seq == 4) e.verification = &*v;
            e.drift = {{"Diameter 3", "DRIFT_UP"}, {"Diameter 1", "DRIFT_DOWN"}};
            ASSERT_TRUE(log->append(e).ok());
            EXPECT_EQ(results::csv_row_of_line(log->last_line()),
                      seq == 4 ? results::verification_csv_row(e) : results::csv_row(e));
        }
        for (const auto& f : std::filesystem::directory_iterator(dir))
            if (f.path().extension() == ".csv") whole[f.path()] = lines(f.path());
    }
    ASSERT_EQ(whole.size(), 3u);  // the day's, hub-b's and the verification file
    // The drift cell in the recipe's feature order, as the entry gave it before it was a line.
    EXPECT_NE(whole.at(dir / (results::local_date(kNoon) + ".csv"))[1].find(
                  ",Diameter 1 DRIFT_DOWN; Diameter 3 DRIFT_UP,"),
              std::string::npos);
    // The crash: sequences 4..6 never reached their CSV files (3 and 2 rows cut off the end, one
    // a torn half row), then the next start.
    const auto cut = [&](const std::filesystem::path& file, std::size_t keep, bool torn) {
        std::ofstream out(file, std::ios::trunc);
        for (std::size_t i = 0; i < keep; ++i) out << whole.at(file)[i] << "\n";
        if (torn) out << whole.at(file)[keep].substr(0, 20);
    };
    const auto day = dir / (results::local_date(kNoon) + ".csv");
    const auto hub_b = dir / (results::local_date(kNoon) + ".hub-b.csv");
    const auto checks = dir / (results::local_date(kNoon) + ".verification.csv");
    cut(day, 3, true);      // header, 1, 2 (5 lost, a torn start of it left)
    cut(hub_b, 2, false);   // header, 3 (6 lost)
    cut(checks, 1, false);  // header (4 lost)
    auto again = results::ResultsLog::open({dir, false});
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(again->completed_at_open(), (std::vector<std::uint64_t>{4, 5, 6}));
    for (const auto& [file, rows] : whole) EXPECT_EQ(lines(file), rows) << file;
    // Opened once more: nothing is owed, nothing written twice.
    auto third = results::ResultsLog::open({dir, false});
    ASSERT_TRUE(third.ok());
    EXPECT_TRUE(third->completed_at_open().empty());
    for (const auto& [file, rows] : whole) EXPECT_EQ(lines(file), rows) << file;
}

// The first start after an upgrade that changed the CSV header (issue 39 added remeasure_of):
// the rows already in the day's CSV under the old header are not written again into the new
// header's file; the one a crash left out is. And more CSV files than the log keeps open (days
// and recipes) do not stop the start.
TEST(ResultsLog, RowsUnderAnOlderHeaderAreNotWrittenAgain) {
    test::TempDir tmp;
    const auto dir = tmp.path / "results";
    const auto a = part("A-1", 3, 60.0);
    std::vector<std::string> rows;
    {
        auto log = results::ResultsLog::open({dir, false});
        ASSERT_TRUE(log.ok());
        for (std::uint64_t seq = 1; seq <= 12; ++seq) {  // more day files than are kept open
            const std::int64_t day = static_cast<std::int64_t>(seq) * 86'400'000'000'000;
            ASSERT_TRUE(log->append({kNoon + day, seq, &a, "v", "h", std::nullopt}).ok());
        }
        rows = lines(log->last_csv());
    }
    // The last day's CSV as the older version wrote it: no remeasure_of column, part 12 missing.
    const auto day12 = dir / (results::local_date(kNoon + 12 * 86'400'000'000'000) + ".csv");
    ASSERT_EQ(rows.size(), 2u);
    std::string old_header = rows[0];
    old_header.replace(old_header.find(",remeasure_of"), 13, "");
    std::ofstream(day12, std::ios::trunc) << old_header << "\n";
    const auto day11 = dir / (results::local_date(kNoon + 11 * 86'400'000'000'000) + ".csv");
    std::vector<std::string> old11 = lines(day11);
    old11[0] = old_header;  // part 11's row under the old header
    {
        std::ofstream out(day11, std::ios::trunc);
        for (const auto& l : old11) out << l << "\n";
    }
    auto again = results::ResultsLog::open({dir, false});
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(again->completed_at_open(), (std::vector<std::uint64_t>{12}));
    EXPECT_EQ(lines(day11), old11) << "part 11 is there, under the old header";
    EXPECT_FALSE(std::filesystem::exists(dir / (day11.stem().string() + ".hub-a.csv")));
    const auto moved = dir / (day12.stem().string() + ".hub-a.csv");  // the new header's file
    EXPECT_EQ(lines(moved), rows);
}

TEST(ResultsLog, TheLastResultLinesSpanDayFilesAndLeaveATornLineOut) {
    test::TempDir tmp;
    std::ofstream(tmp.path / "2026-12-01.jsonl") << "{\"sequence\":1}\n{\"sequence\":2}\n";
    std::ofstream(tmp.path / "2026-12-02.jsonl") << "{\"sequence\":3}\n{\"sequence\":4}\n{\"seq";
    EXPECT_EQ(
        results::last_result_lines(tmp.path, 3),
        (std::vector<std::string>{"{\"sequence\":2}", "{\"sequence\":3}", "{\"sequence\":4}"}));
    EXPECT_EQ(results::last_result_lines(tmp.path, 10).size(), 4u);
    EXPECT_TRUE(results::last_result_lines(tmp.path / "none", 10).empty());
}

core::Recording small_recording(const std::string& id) {
    core::Recording rec;
    rec.part_id = id;
    rec.recipe = "hub-a";
    rec.captured_at = "2026-11-18T12:00:00Z";
    rec.temperature_c = 1000.0;
    core::FaceScan f;
    f.name = "top";
    f.width = 64;
    for (int k = 0; k < 50; ++k) {
        f.profile_times_ns.push_back(1'000'000'000LL + k * 1'000'000LL);
        f.profile_positions_mm.push_back(0.2 * k);
        for (int i = 0; i < 64; ++i) {
            f.profiles_mm.push_back(static_cast<float>(i));
            f.profiles_mm.push_back(900.0f);
        }
    }
    rec.faces.push_back(std::move(f));
    return rec;
}

TEST(RawArchive, KeepsBadPartsAndEveryNthOkWithinItsQuotaOldestFirst) {
    test::TempDir tmp;
    const auto one = [&] {  // the size of one archived recording
        test::TempDir probe;
        EXPECT_TRUE(io::write_recording(small_recording("X"), probe.path / "r").ok());
        std::uint64_t n = 0;
        for (const auto& e : std::filesystem::recursive_directory_iterator(probe.path))
            if (e.is_regular_file()) n += e.file_size();
        return n;
    }();
    auto archive = results::RawArchive::open({tmp.path / "archive", one * 5 / 2, 10});
    ASSERT_TRUE(archive.ok()) << archive.error().message;

    auto ok = part("A", 3, 60.0);
    EXPECT_FALSE(archive->wants(ok, 7));
    EXPECT_TRUE(archive->wants(ok, 20));  // every 10th OK part
    auto nok = ok;
    nok.measurement.verdict = measure::Verdict::kNok;
    EXPECT_TRUE(archive->wants(nok, 7));
    auto degraded = ok;
    degraded.degraded = true;
    EXPECT_TRUE(archive->wants(degraded, 7));

    std::vector<std::filesystem::path> stored;
    for (int seq = 1; seq <= 5; ++seq) {
        auto where = archive->store(small_recording("P/" + std::to_string(seq)), seq,
                                    kNoon + seq * 1'000'000'000LL);
        ASSERT_TRUE(where.ok()) << where.error().message;
        stored.push_back(*where);
    }
    EXPECT_LE(archive->used_bytes(), one * 5 / 2);
    // The two newest remain, whole and readable again; the oldest went first.
    for (int i = 0; i < 3; ++i) EXPECT_FALSE(std::filesystem::exists(stored[i])) << stored[i];
    for (int i = 3; i < 5; ++i) {
        auto back = io::read_recording(stored[i]);
        ASSERT_TRUE(back.ok()) << back.error().message;
        EXPECT_EQ(back->part_id, "P/" + std::to_string(i + 1));
        EXPECT_EQ(back->faces.at(0).n_profiles(), 50);
    }
    EXPECT_EQ(stored[4].filename().string(), "000000000005_P_5");  // a safe folder name
}

// The archive follows the commit: a recording is under its final name only once whole, and a
// committed line naming a folder a crash never wrote gets that folder with a note saying so,
// which `hotgauge report part --results` reads back as the reason.
TEST(RawArchive, AFolderACrashNeverWroteIsSaidSoAtTheNextStart) {
    test::TempDir tmp;
    auto archive = results::RawArchive::open({tmp.path / "archive", 1ull << 30, 1});
    ASSERT_TRUE(archive.ok());
    auto stored = archive->store(small_recording("P-1"), 1, kNoon);
    ASSERT_TRUE(stored.ok()) << stored.error().message;
    auto leftover = *stored;
    leftover += ".partial";
    EXPECT_FALSE(std::filesystem::exists(leftover));
    // Part 2's line was committed, then the daemon died while writing its recording.
    const auto lost = archive->folder("P-2", 2, kNoon);
    std::filesystem::create_directories(lost.string() + ".partial");
    std::ofstream(lost.string() + ".partial/manifest.yaml") << "format: hotgauge-re";
    const auto results_dir = tmp.path / "results";
    std::filesystem::create_directories(results_dir);
    std::vector<std::string> committed;
    // Part 0's folder was deleted for the quota (older than a folder still there): not marked.
    const auto deleted = archive->folder("P-0", 0, kNoon);
    for (auto [seq, where] : {std::pair{0, deleted}, std::pair{1, *stored}, std::pair{2, lost}}) {
        nlohmann::json j{{"sequence", seq},
                         {"time", "2026-11-18T12:00:00.000+00:00"},
                         {"archived_as", where.string()},
                         {"part", {{"part_id", "P-" + std::to_string(seq)}}}};
        committed.push_back(j.dump());
    }
    committed.push_back(R"({"sequence":3,"archived_as":null})");  // not archived: nothing to do
    {
        std::ofstream out(results_dir / "2026-11-18.jsonl");
        for (const auto& l : committed) out << l << "\n";
    }
    EXPECT_EQ(archive->complete(committed), (std::vector<std::filesystem::path>{lost}));
    EXPECT_FALSE(std::filesystem::exists(deleted));
    EXPECT_FALSE(std::filesystem::exists(lost.string() + ".partial"));
    EXPECT_TRUE(std::filesystem::exists(lost / results::RawArchive::kNotArchived));
    EXPECT_TRUE(io::read_recording(*stored).ok());  // the whole one untouched
    auto back = results::archived_recording(results_dir, 2);
    ASSERT_FALSE(back.ok());
    EXPECT_NE(back.error().message.find("2026-11-18.jsonl:3: part sequence 2 has no recording"),
              std::string::npos)
        << back.error().message;
    EXPECT_NE(back.error().message.find("hotgauged stopped"), std::string::npos);
    EXPECT_TRUE(results::archived_recording(results_dir, 1).ok());
    EXPECT_TRUE(archive->complete(committed).empty()) << "said once";
    // A store() that failed while the daemon runs says why at once.
    const auto failed = archive->folder("P-4", 4, kNoon);
    const nlohmann::json line4{{"sequence", 4}, {"archived_as", failed.string()}};
    EXPECT_TRUE(archive->not_archived(line4.dump(), "writing it failed: No space left on device"));
    std::ifstream note(failed / results::RawArchive::kNotArchived);
    std::string text;
    std::getline(note, text);
    EXPECT_NE(text.find("was not archived: writing it failed: No space left on device"),
              std::string::npos)
        << text;
}

TEST(ResultsLog, TheLastSequenceComesFromTheNewestDaysLastWholeLine) {
    test::TempDir tmp;
    EXPECT_EQ(results::last_sequence(tmp.path / "none"), 0u) << "no folder: start at 1";
    std::ofstream(tmp.path / "2026-11-20.jsonl") << "{\"sequence\": 7}\n{\"sequence\": 8}\n";
    EXPECT_EQ(results::last_sequence(tmp.path), 8u);
    // A newer day whose last line is torn: its last whole line counts. The line is longer than
    // one read block, so the search for its start reads back more than once.
    const std::string pad(100'000, 'x');
    std::ofstream(tmp.path / "2026-11-21.jsonl")
        << "{\"sequence\": 9}\n{\"pad\": \"" << pad << "\", \"sequence\": 10}\n{\"seq";
    EXPECT_EQ(results::last_sequence(tmp.path), 10u);
    // A newest day without any sequence (empty): the day before it counts.
    std::ofstream(tmp.path / "2026-11-22.jsonl") << "";
    EXPECT_EQ(results::last_sequence(tmp.path), 10u);
}

TEST(ResultsLog, AnUnwritableFolderIsNamed) {
    auto log = results::ResultsLog::open({"/proc/hotgauge-results", true});
    ASSERT_FALSE(log.ok());
    EXPECT_NE(log.error().message.find("/proc/hotgauge-results"), std::string::npos);
}

// The sequence numbers used are kept apart from the results (issue 39): a number reserved and
// never committed (FAULT 206, a crash) is still known after a restart, in place on a full disk,
// and a file that is not a number is refused with its name.
TEST(SequenceReservation, KeepsTheHighestNumberUsedAcrossReopeningAndAFullDisk) {
    test::TempDir tmp;
    {
        auto s = results::SequenceReservation::open(tmp.path);
        ASSERT_TRUE(s.ok()) << s.error().message;
        EXPECT_EQ(s->reserved(), 0u);
        EXPECT_FALSE(s->last().unfinished());
        ASSERT_TRUE(s->reserve(41, 7001, 1).ok());
        EXPECT_TRUE(s->last().unfinished());
        ASSERT_TRUE(s->taken().ok());  // the PLC took part 41's result
        EXPECT_FALSE(s->last().unfinished());
        EXPECT_EQ(results::SequenceReservation::open(tmp.path)->last().state, 'D') << "on disk";
        ASSERT_TRUE(s->reserve(42, 4294967295u, 65535).ok());
    }
    {
        // Killed after reserving: the next start knows which part that was.
        auto s = results::SequenceReservation::open(tmp.path);
        ASSERT_TRUE(s.ok());
        EXPECT_EQ(s->reserved(), 42u);
        EXPECT_EQ(s->last().part_id, 4294967295u);
        EXPECT_EQ(s->last().slot, 65535);
        EXPECT_TRUE(s->last().unfinished());
        ASSERT_TRUE(s->stopped().ok());
    }
    {
        auto s = results::SequenceReservation::open(tmp.path);
        ASSERT_TRUE(s.ok());
        EXPECT_EQ(s->reserved(), 42u);
        EXPECT_EQ(s->last().state, 'S') << "stopped cleanly";
        EXPECT_EQ(s->last().part_id, 4294967295u);
        // A full disk (no file may grow past its size): the number is written in place.
        signal(SIGXFSZ, SIG_IGN);
        rlimit old{};
        getrlimit(RLIMIT_FSIZE, &old);
        rlimit none = old;
        none.rlim_cur = std::filesystem::file_size(tmp.path / ".sequence");
        ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &none), 0);
        const auto kept = s->reserve(18446744073709551615ull);
        setrlimit(RLIMIT_FSIZE, &old);
        signal(SIGXFSZ, SIG_DFL);
        EXPECT_TRUE(kept.ok()) << kept.error().message;
    }
    EXPECT_EQ(results::SequenceReservation::open(tmp.path)->reserved(), 18446744073709551615ull);
    std::ofstream(tmp.path / ".sequence") << "                  17\n";  // the first format
    EXPECT_EQ(results::SequenceReservation::open(tmp.path)->last().sequence, 17u);
    EXPECT_EQ(results::SequenceReservation::open(tmp.path)->last().state, 'S');
    std::ofstream(tmp.path / ".sequence") << "17 7001 1 X\n";
    EXPECT_FALSE(results::SequenceReservation::open(tmp.path).ok()) << "no such state";
    std::ofstream(tmp.path / ".sequence") << "forty-two\n";
    const auto bad = results::SequenceReservation::open(tmp.path);
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find(".sequence"), std::string::npos) << bad.error().message;
}

}  // namespace
}  // namespace hotgauge
