// The daemon's cell logic in-process (no camera): what happens to a trigger that cannot be
// measured, sequence numbers across restarts, config reload, stop. The camera and the whole
// line are in the integration tests (virtual_line.py, daemon_faults_test.py); this one also
// runs under ASan/UBSan.
#include <gtest/gtest.h>
#include <modbus.h>

#include <chrono>
#include <fstream>
#include <sstream>
#include <thread>

#include "hotgauge/cell/daemon.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/model/model_io.hpp"
#include "hotgauge/pipeline/pipeline.hpp"
#include "hotgauge/plc/register_map.hpp"
#include "hotgauge/vcell/axis_server.hpp"
#include "temp_dir.hpp"

namespace hotgauge {
namespace {

using namespace std::chrono_literals;

std::string config_text(const std::filesystem::path& results,
                        const std::string& axis = "axis:\n  kind: none\n") {
    const std::string src = HOTGAUGE_SOURCE_DIR;
    return "calibration: " + src + "/config/calibration.yaml\n" +
           "faces: [top, bottom, side1, side2]\n" + "recipes:\n  1: " + src +
           "/config/parts/hub-a.yaml\n" +
           "camera:\n  id: NO-SUCH-CAMERA\n  mode: peaks\n  height: 10\n  scan_s: 0.5\n" +
           "accelerometer:\n  source: none\n" + axis +
           "plc:\n  bind_address: 127.0.0.1\n  port: 0\n" + "results:\n  dir: " + results.string() +
           "\n  archive_dir: " + (results / "archive").string() + "\n";
}

void write(const std::filesystem::path& p, const std::string& text) { std::ofstream(p) << text; }

// A PLC on the daemon's port.
class Plc {
  public:
    explicit Plc(int port) : ctx_(modbus_new_tcp("127.0.0.1", port)) {
        modbus_set_response_timeout(ctx_, 2, 0);
        ok_ = modbus_connect(ctx_) == 0;
    }
    ~Plc() {
        modbus_close(ctx_);
        modbus_free(ctx_);
    }
    bool ok() const { return ok_; }
    std::uint16_t input(int address) {
        std::uint16_t v = 0xFFFF;
        modbus_read_input_registers(ctx_, address, 1, &v);
        return v;
    }
    void command(std::uint16_t cmd, std::uint16_t slot = 1, std::uint16_t face = 1) {
        const std::uint16_t regs[6] = {cmd, 0, 77, slot, face, 0};
        modbus_write_registers(ctx_, 0, cmd == 1 ? 6 : 1, regs);
    }
    // Waits for the state register to read `state`; false after `timeout`.
    bool wait_state(plc::State state, std::chrono::milliseconds timeout) {
        const auto end = std::chrono::steady_clock::now() + timeout;
        while (std::chrono::steady_clock::now() < end) {
            if (input(plc::ir::kState) == static_cast<std::uint16_t>(state)) return true;
            std::this_thread::sleep_for(10ms);
        }
        return false;
    }

  private:
    modbus_t* ctx_;
    bool ok_ = false;
};

std::vector<std::string> lines_of(const std::filesystem::path& p) {
    std::ifstream in(p);
    std::vector<std::string> out;
    for (std::string line; std::getline(in, line);) out.push_back(line);
    return out;
}

TEST(Daemon, ACameraThatIsNotThereFailsThePartWithItsReasonAndTheDaemonGoesOn) {
    test::TempDir dir;
    const auto results = dir.path / "results";
    std::filesystem::create_directories(results);
    // Yesterday's file ended at sequence 41: numbering goes on from there.
    write(results / "2026-11-21.jsonl", "{\"sequence\": 40}\n{\"sequence\": 41}\n");
    const auto config = dir.path / "hotgauged.yaml";
    write(config, config_text(results));

    auto setup = cell::load_setup(config);
    ASSERT_TRUE(setup) << setup.error().message;
    std::vector<std::string> status;
    std::mutex status_mutex;
    bool ready = false;
    cell::Supervisor sup;
    sup.ready = [&] { ready = true; };
    sup.status = [&](const std::string& s) {
        std::lock_guard lock(status_mutex);
        status.push_back(s);
    };
    auto daemon = cell::Daemon::start(*setup, sup);
    ASSERT_TRUE(daemon) << daemon.error().message;
    EXPECT_TRUE(ready);
    EXPECT_EQ((*daemon)->stats().next_sequence, 42u);
    std::thread control([&] { (*daemon)->run(); });

    Plc plc((*daemon)->plc_port());
    ASSERT_TRUE(plc.ok());
    EXPECT_EQ(plc.input(plc::ir::kSequence), 41) << "the PLC's count goes on from the files";
    // No recipe in slot 9: fault 202 at once, and no sequence number is used.
    plc.command(1, 9);
    ASSERT_TRUE(plc.wait_state(plc::State::kFault, 5s));
    EXPECT_EQ(plc.input(plc::ir::kErrorCode), 202);
    plc.command(3);
    ASSERT_TRUE(plc.wait_state(plc::State::kIdle, 5s));

    // Slot 1, top face: the camera is not there, the part fails with 203 and has its row.
    plc.command(1, 1, 1);
    ASSERT_TRUE(plc.wait_state(plc::State::kFault, 30s));
    EXPECT_EQ(plc.input(plc::ir::kErrorCode), 203);
    // The registers come first, the daemon's counts just after them: wait for those (bounded).
    for (int i = 0; i < 200 && (*daemon)->stats().failed < 2; ++i)
        std::this_thread::sleep_for(10ms);
    const auto stats = (*daemon)->stats();
    EXPECT_EQ(stats.triggers, 2u);
    EXPECT_EQ(stats.failed, 2u);
    EXPECT_EQ(stats.next_sequence, 43u);
    std::filesystem::path jsonl;
    for (const auto& e : std::filesystem::directory_iterator(results))
        if (e.path().extension() == ".jsonl" && e.path().filename() != "2026-11-21.jsonl")
            jsonl = e.path();
    ASSERT_FALSE(jsonl.empty()) << "no results file for today";
    const auto lines = lines_of(jsonl);
    ASSERT_EQ(lines.size(), 1u);
    EXPECT_NE(lines[0].find("\"sequence\":42"), std::string::npos) << lines[0];
    EXPECT_NE(lines[0].find("NO-SUCH-CAMERA"), std::string::npos) << "the reason names the camera";
    EXPECT_NE(lines[0].find("NOT_MEASURED"), std::string::npos);
    auto csv = jsonl;
    csv.replace_extension(".csv");
    EXPECT_EQ(lines_of(csv).size(), 2u) << "header and one row";

    // A broken config at reload is rejected and the daemon keeps serving; a good one is taken.
    write(config, "camera: [unclosed\n");
    (*daemon)->request_reload();
    const auto until = std::chrono::steady_clock::now() + 5s;
    while ((*daemon)->stats().rejected_reloads == 0 && std::chrono::steady_clock::now() < until)
        std::this_thread::sleep_for(20ms);
    EXPECT_EQ((*daemon)->stats().rejected_reloads, 1u);
    // A recipe path the filesystem cannot look at (a symlink loop) made the reader throw and
    // killed the daemon (issue 18, finding 2): rejected like any other mistake.
    const auto loop = results / "loop";
    std::filesystem::create_symlink(loop, loop);
    std::string looped = config_text(results);
    const std::string recipe = std::string(HOTGAUGE_SOURCE_DIR) + "/config/parts/hub-a.yaml";
    looped.replace(looped.find(recipe), recipe.size(), (loop / "hub-a.yaml").string());
    write(config, looped);
    (*daemon)->request_reload();
    const auto until_loop = std::chrono::steady_clock::now() + 5s;
    while ((*daemon)->stats().rejected_reloads == 1 &&
           std::chrono::steady_clock::now() < until_loop)
        std::this_thread::sleep_for(20ms);
    EXPECT_EQ((*daemon)->stats().rejected_reloads, 2u);
    plc.command(3);
    EXPECT_TRUE(plc.wait_state(plc::State::kIdle, 5s)) << "still serving the PLC";
    // STATUS= follows the registers from the daemon's own thread: wait (bounded) for the idle
    // state's, so that the good reload below does not overtake it.
    const auto idle_said = [&] {
        std::lock_guard lock(status_mutex);
        const auto rejected = std::find_if(status.begin(), status.end(), [](const auto& s) {
            return s.find("— reload rejected at ") != std::string::npos;
        });
        return rejected != status.end() &&
               std::any_of(rejected + 1, status.end(),
                           [](const auto& s) { return s.rfind("idle", 0) == 0; });
    };
    for (int i = 0; i < 250 && !idle_said(); ++i) std::this_thread::sleep_for(20ms);
    write(config, config_text(results));
    (*daemon)->request_reload();
    const auto until2 = std::chrono::steady_clock::now() + 5s;
    while ((*daemon)->stats().reloads == 0 && std::chrono::steady_clock::now() < until2)
        std::this_thread::sleep_for(20ms);
    EXPECT_EQ((*daemon)->stats().reloads, 1u);
    {
        std::lock_guard lock(status_mutex);
        // Issue 39: the rejection stays in STATUS= through the state changes after it, until
        // a reload succeeds.
        const auto rejected = std::find_if(status.begin(), status.end(), [](const auto& s) {
            return s.find("— reload rejected at ") != std::string::npos;
        });
        ASSERT_NE(rejected, status.end());
        EXPECT_NE(rejected->find("hotgauged.yaml"), std::string::npos) << *rejected;
        EXPECT_TRUE(std::any_of(rejected + 1, status.end(), [](const auto& s) {
            return s.rfind("idle", 0) == 0 && s.find("reload rejected") != std::string::npos;
        })) << "an idle state after the rejection still says so";
        EXPECT_EQ(status.back().find("reload rejected"), std::string::npos)
            << "after the good reload: " << status.back();
        EXPECT_TRUE(std::any_of(status.begin(), status.end(),
                                [](const auto& s) { return s.rfind("busy: part 77", 0) == 0; }));
    }

    const auto t0 = std::chrono::steady_clock::now();
    (*daemon)->request_stop();
    control.join();
    EXPECT_LT(std::chrono::steady_clock::now() - t0, 5s);
}

TEST(Daemon, AnAxisThatDoesNotArriveInTimeIsATimeout) {
    vcell::AxisServerConfig ac;
    ac.move_time_s = 30.0;  // far longer than the daemon's axis timeout
    auto axis = vcell::AxisServer::start(ac, {});
    ASSERT_TRUE(axis) << axis.error().message;
    test::TempDir dir;
    const auto config = dir.path / "hotgauged.yaml";
    write(config, config_text(dir.path / "results",
                              "axis:\n  kind: modbus\n  address: 127.0.0.1:" +
                                  std::to_string((*axis)->port()) +
                                  "\n  faces: {top: 1, bottom: 2, side1: 3, side2: 4}\n"
                                  "  timeout_ms: 300\n"));
    auto setup = cell::load_setup(config);
    ASSERT_TRUE(setup) << setup.error().message;
    auto daemon = cell::Daemon::start(*setup);
    ASSERT_TRUE(daemon) << daemon.error().message;
    std::thread control([&] { (*daemon)->run(); });
    Plc plc((*daemon)->plc_port());
    ASSERT_TRUE(plc.ok());
    // A cycle the PLC resets while BUSY: its failure must not reach the registers afterwards.
    plc.command(1, 1, 2);  // the bottom face: the axis must move
    ASSERT_TRUE(plc.wait_state(plc::State::kBusy, 5s));
    plc.command(3);
    ASSERT_TRUE(plc.wait_state(plc::State::kIdle, 5s));
    const auto until = std::chrono::steady_clock::now() + 10s;
    while ((*daemon)->stats().failed == 0 && std::chrono::steady_clock::now() < until)
        std::this_thread::sleep_for(20ms);
    EXPECT_EQ((*daemon)->stats().failed, 1u) << "the abandoned part is accounted for";
    std::this_thread::sleep_for(200ms);
    EXPECT_EQ(plc.input(plc::ir::kState), static_cast<std::uint16_t>(plc::State::kIdle));
    // The next part: the axis does not arrive, a timeout.
    plc.command(1, 1, 3);
    ASSERT_TRUE(plc.wait_state(plc::State::kFault, 30s));
    EXPECT_EQ(plc.input(plc::ir::kErrorCode), 204);
    (*daemon)->request_stop();
    control.join();
}

TEST(Daemon, ASetupWithAMissingRecipeIsAnErrorNamingIt) {
    test::TempDir dir;
    const auto config = dir.path / "hotgauged.yaml";
    std::string text = config_text(dir.path / "results");
    const std::string from = "/config/parts/hub-a.yaml";
    text.replace(text.find(from), from.size(), "/config/parts/no-such-part.yaml");
    write(config, text);
    auto setup = cell::load_setup(config);
    ASSERT_FALSE(setup);
    EXPECT_NE(setup.error().message.find("no-such-part.yaml"), std::string::npos)
        << setup.error().message;
}

// A recipe the cell cannot run is refused when the setup loads (--check-config, start and
// reload), naming the feature (issue 40): one on a face the cell does not scan, a slot above the
// register map's 16, 17 features, two features on one slot (the recipe reader's own check).
TEST(Daemon, ARecipeTheCellCannotRunIsRefusedNamingTheFeature) {
    test::TempDir dir;
    const auto config = dir.path / "hotgauged.yaml";
    const std::string src = HOTGAUGE_SOURCE_DIR;
    std::ifstream in(src + "/config/parts/hub-a.yaml");
    const std::string hub_a{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
    const auto refused = [&](const std::string& recipe, const std::string& faces) {
        write(dir.path / "part.yaml", recipe);
        std::string text = config_text(dir.path / "results");
        text.replace(text.find(src + "/config/parts/hub-a.yaml"),
                     (src + "/config/parts/hub-a.yaml").size(), (dir.path / "part.yaml").string());
        text.replace(text.find("faces: [top, bottom, side1, side2]"), 34, faces);
        write(config, text);
        auto setup = cell::load_setup(config);
        return setup ? std::string("loaded") : setup.error().message;
    };
    EXPECT_EQ(refused(hub_a, "faces: [top, bottom, side1, side2]"), "loaded");
    const std::string all = "faces: [top, bottom, side1, side2]";
    // Diameter 1 is measured on the bottom face and the sides.
    const auto no_bottom = refused(hub_a, "faces: [top, side1, side2]");
    EXPECT_NE(no_bottom.find("feature 'Diameter 1' (slot 1) needs face 'bottom', which the cell "
                             "does not scan"),
              std::string::npos)
        << no_bottom;
    std::string slot17 = hub_a;
    slot17.replace(slot17.find("slot: 14"), 8, "slot: 17");
    const auto high = refused(slot17, all);
    EXPECT_NE(high.find("feature 'Die shift': slot 17 is outside 1..16; the PLC's register map "
                        "holds 16 feature blocks"),
              std::string::npos)
        << high;
    std::string twice = hub_a;
    twice.replace(twice.find("slot: 14"), 8, "slot: 13");
    const auto same = refused(twice, all);
    EXPECT_NE(
        same.find("feature 'Die shift' on slot 13, which feature 'Height 4 side2' has already"),
        std::string::npos)
        << same;
}

// The part's model (pipeline::part_model, the tool's and the daemon's one way): a saved model of
// another part is refused at start naming the file and both parts; the recipe's own loads, and
// is the model the recipe builds.
TEST(Daemon, ASavedModelMustBeTheSlotsPart) {
    test::TempDir dir;
    auto recipe = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
    ASSERT_TRUE(recipe) << recipe.error().message;
    auto built = pipeline::part_model(*recipe);
    ASSERT_TRUE(built) << built.error().message;
    const auto own = dir.path / "hub-a.hgm", other = dir.path / "hub-b.hgm";
    ASSERT_TRUE(model::write_model(*built, own));
    match::Model renamed = *built;
    renamed.name = "hub-b";
    ASSERT_TRUE(model::write_model(renamed, other));
    const auto config = dir.path / "hotgauged.yaml";
    write(config, config_text(dir.path / "results") + "models:\n  1: " + other.string() + "\n");
    auto setup = cell::load_setup(config);
    ASSERT_FALSE(setup);
    EXPECT_NE(setup.error().message.find("recipe slot 1: " + other.string() +
                                         ": model of part 'hub-b', the recipe is 'hub-a'"),
              std::string::npos)
        << setup.error().message;
    write(config, config_text(dir.path / "results") + "models:\n  1: " + own.string() + "\n");
    setup = cell::load_setup(config);
    ASSERT_TRUE(setup) << setup.error().message;
    const match::Model& loaded = *(*setup)->models.at(1);
    EXPECT_EQ(loaded.name, "hub-a");
    EXPECT_EQ(loaded.points.size(), built->points.size());
    auto same = pipeline::part_model(*recipe, {.model_file = own});
    ASSERT_TRUE(same) << same.error().message;
    EXPECT_EQ(same->points.size(), built->points.size());
    EXPECT_FALSE(pipeline::part_model(*recipe, {.model_file = dir.path / "missing.hgm"}));
}

// A master slot's certificate must fit its recipe (docs/verification.md): another recipe's, or
// one certifying a feature the recipe lacks, is refused at start, naming the file; a fitting
// one loads and is described.
TEST(Daemon, AMasterCertificateMustFitItsSlotsRecipe) {
    test::TempDir dir;
    const auto cert = dir.path / "master.yaml";
    const auto config = dir.path / "hotgauged.yaml";
    write(config, config_text(dir.path / "results") + "masters:\n  1: " + cert.string() + "\n");
    const std::string head =
        "format: hotgauge-master-1\nmaster: M-1\ncertified_at: \"2026-11-20\"\n"
        "certified_by: lab\ntemperature_c: 20.0\ntolerance_mm: 0.02\n";
    write(
        cert,
        head + "recipe: hub-b\nfeatures: [{name: \"Diameter 1\", value_mm: 138.4, u_mm: 0.001}]\n");
    auto setup = cell::load_setup(config);
    ASSERT_FALSE(setup);
    EXPECT_NE(setup.error().message.find("master of recipe 'hub-b', recipe slot 1 is 'hub-a'"),
              std::string::npos)
        << setup.error().message;
    write(cert,
          head + "recipe: hub-a\nfeatures: [{name: \"Diameter 9\", value_mm: 1.0, u_mm: 0.001}]\n");
    setup = cell::load_setup(config);
    ASSERT_FALSE(setup);
    EXPECT_NE(setup.error().message.find("certified feature 'Diameter 9' is not in recipe hub-a"),
              std::string::npos)
        << setup.error().message;
    write(
        cert,
        head + "recipe: hub-a\nfeatures: [{name: \"Diameter 1\", value_mm: 138.4, u_mm: 0.001}]\n");
    setup = cell::load_setup(config);
    ASSERT_TRUE(setup) << setup.error().message;
    EXPECT_NE(cell::describe(**setup).find("master M-1 (certified 2026-11-20, 1 features)"),
              std::string::npos)
        << cell::describe(**setup);
}

}  // namespace
}  // namespace hotgauge

namespace hotgauge {

// Every result carries a hash over everything that decided it (issue 20): the same files give
// the same hash; a recipe whose tolerance changed, or another calibration, gives another.
TEST(Daemon, TheResultHashChangesWithTheRecipeAndTheGeometry) {
    test::TempDir dir;
    const std::string src = HOTGAUGE_SOURCE_DIR;
    const auto recipe = dir.path / "hub-a.yaml", cal = dir.path / "calibration.yaml";
    std::filesystem::copy_file(src + "/config/parts/hub-a.yaml", recipe);
    std::filesystem::copy_file(src + "/config/calibration.yaml", cal);
    std::string text = config_text(dir.path / "results");
    for (const auto& [from, to] : {std::pair{src + "/config/parts/hub-a.yaml", recipe.string()},
                                   std::pair{src + "/config/calibration.yaml", cal.string()}})
        text.replace(text.find(from), from.size(), to);
    const auto config = dir.path / "hotgauged.yaml";
    write(config, text);
    auto hash = [&] {
        auto setup = cell::load_setup(config);
        EXPECT_TRUE(setup) << setup.error().message;
        return setup ? (*setup)->result_hash.at(1) : std::string();
    };
    const std::string first = hash();
    EXPECT_EQ(first.size(), 16u);
    EXPECT_EQ(hash(), first);
    // A tolerance of the recipe: one character.
    std::ifstream in(recipe);
    std::string r((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const auto at = r.find("tolerance");
    ASSERT_NE(at, std::string::npos);
    const auto digit = r.find_first_of("123456789", at);
    r[digit] = r[digit] == '9' ? '8' : static_cast<char>(r[digit] + 1);
    write(recipe, r);
    const std::string changed = hash();
    EXPECT_NE(changed, first);
    std::ofstream(cal, std::ios::app) << "# recalibrated\n";
    EXPECT_NE(hash(), changed);
}

}  // namespace hotgauge
