// hotgauge plc: the PLC interface for integrators and tests (docs/plc-modbus.md).
//   plc serve          the Modbus TCP server with a scripted stand-in cell (demo results)
//   plc map            the register map tables, as in the docs
//   plc pyrometer      read the pyrometer over Modbus RTU and print (commissioning)
//   plc pyrometer-sim  a simulated pyrometer (Modbus RTU slave) on a serial device
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <thread>

#include "commands.hpp"
#include "hotgauge/cell/config.hpp"
#include "hotgauge/cell/plc_sections.hpp"
#include "hotgauge/core/clock.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/io/yaml_reader.hpp"
#include "hotgauge/plc/pyrometer.hpp"
#include "hotgauge/plc/server.hpp"

namespace hotgauge::app {
namespace {

using Clock = std::chrono::steady_clock;

volatile std::sig_atomic_t g_stop = 0;
extern "C" void on_signal(int) { g_stop = 1; }

void stop_on_signals() {
    struct sigaction sa {};
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);
}

struct PlcFileConfig {
    plc::ServerConfig server;
    plc::PyrometerConfig pyrometer;
};

// config/plc.yaml; every error names file:line and the key.
core::Result<PlcFileConfig> read_plc_config(const std::string& file) {
    const io::YamlReader y(file);
    return y.guarded<PlcFileConfig>([&] {
        const YAML::Node root = y.load();
        y.expect_map(root, "plc", {"server", "pyrometer"});
        PlcFileConfig c;
        if (const YAML::Node s = root["server"]) cell::read_plc_server(y, s, "server", c.server);
        if (const YAML::Node p = root["pyrometer"])
            cell::read_pyrometer(y, p, "pyrometer", c.pyrometer);
        return c;
    });
}

// ---- plc serve -------------------------------------------------------------------------------

// Part ids that make the stand-in cell misbehave on purpose (documented in docs/plc-modbus.md).
constexpr std::uint32_t kFaultPart = 999999;        // FAULT 201 (measurement failed)
constexpr std::uint32_t kNotMeasuredPart = 999998;  // slot 3 not measured
constexpr std::uint32_t kNokPart = 999997;          // slot 1 nominal + 1.000 mm: NOK
constexpr std::uint32_t kDegradedPart = 999996;     // slot 4 degraded (+1 mm), overall degraded

struct ServeArgs {
    std::string config = HOTGAUGE_CONFIG_DIR "/plc.yaml";
    std::string recipe = HOTGAUGE_CONFIG_DIR "/parts/hub-a.yaml";
    std::optional<std::string> bind, word_order;
    std::optional<int> port, max_connections, idle_timeout_ms;
    std::string port_file;
    int busy_ms = 300;
    double duration_s = 0;
};

// The stand-in cell's result: every recipe feature at nominal + ((part id + slot) mod 5 − 2)·10 µm
// held inside its tolerance (a die shift is never below 0), at 1050.0 °C, unless the part id asks
// for trouble.
plc::PartResult demo_result(const core::Recipe& recipe, std::uint32_t part_id,
                            std::uint16_t recipe_revision) {
    plc::PartResult r;
    r.recipe_revision = recipe_revision;
    r.temperature_c = 1050.0;
    for (const auto& f : recipe.features) {
        plc::FeatureValue v;
        v.name = f.name;
        v.slot = f.slot;
        const auto dev_um =
            static_cast<int>((std::uint64_t{part_id} + static_cast<unsigned>(f.slot)) % 5) - 2;
        double value = f.nominal_mm + std::clamp(dev_um * 0.010, f.tol_lower_mm, f.tol_upper_mm);
        if ((part_id == kNokPart && f.slot == 1) || (part_id == kDegradedPart && f.slot == 4))
            value = f.nominal_mm + 1.0;
        if (part_id != kNotMeasuredPart || f.slot != 3) v.value_mm = value;
        const bool outside = value - f.nominal_mm < f.tol_lower_mm - 1e-9 ||
                             value - f.nominal_mm > f.tol_upper_mm + 1e-9;
        if (v.value_mm && outside) v.reasons |= plc::reason::kOutsideTolerance;
        if (!v.value_mm) {
            v.verdict = plc::Verdict::kNotMeasured;
            v.reasons = plc::reason::kNotMeasured;
        } else if (part_id == kDegradedPart && f.slot == 4) {  // out of tolerance, but degraded
            v.verdict = plc::Verdict::kDegraded;
            v.reasons |= plc::reason::kDegraded;
        } else {
            v.verdict = outside ? plc::Verdict::kNok : plc::Verdict::kOk;
        }
        r.features.push_back(v);
    }
    r.overall = plc::overall_verdict(r.features, false);
    r.time_ns = core::realtime_ns();
    return r;
}

bool write_port_file(const std::string& path, int port) {
    const std::string tmp = path + ".tmp";
    {
        std::ofstream out(tmp, std::ios::trunc);
        out << port << "\n";
        if (!out) return false;
    }
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);  // atomic: a reader never sees half a number
    return !ec;
}

int serve(const ServeArgs& a) {
    auto file = read_plc_config(a.config);
    if (!file) {
        spdlog::error("{}", file.error().message);
        return 1;
    }
    plc::ServerConfig config = file->server;
    if (a.bind) config.bind_address = *a.bind;
    if (a.port) config.port = *a.port;
    if (a.max_connections) config.max_connections = *a.max_connections;
    if (a.idle_timeout_ms) config.idle_timeout_ms = *a.idle_timeout_ms;
    if (a.word_order) config.word_order = *plc::parse_word_order(*a.word_order);
    auto recipe = io::read_recipe(a.recipe);
    if (!recipe) {
        spdlog::error("{}", recipe.error().message);
        return 1;
    }
    auto server = plc::Server::start(config);
    if (!server) {
        spdlog::error("{}", server.error().message);
        return 1;
    }
    stop_on_signals();
    auto& s = **server;
    if (!a.port_file.empty() && !write_port_file(a.port_file, s.port())) {
        spdlog::error("cannot write the port file {}", a.port_file);
        return 1;
    }
    std::printf(
        "hotgauge plc serve: listening on %s:%d, stand-in cell with recipe %s in slot 1, "
        "%d ms per part\n",
        config.bind_address.c_str(), s.port(), recipe->name.c_str(), a.busy_ms);
    std::fflush(stdout);

    std::optional<plc::TriggerRequest> pending;
    Clock::time_point due, scanned;  // the stand-in's scans take half its time
    bool scans_reported = false;
    const std::uint16_t revision = cell::recipe_revision(a.recipe);
    const auto end = Clock::now() + std::chrono::duration<double>(a.duration_s);
    while (!g_stop && (a.duration_s <= 0 || Clock::now() < end)) {
        const auto next = scans_reported ? due : scanned;  // the stand-in's next step
        const auto wait = pending ? std::chrono::ceil<std::chrono::milliseconds>(
                                        std::max(next - Clock::now(), Clock::duration{}))
                                  : std::chrono::milliseconds(100);
        if (auto e = s.wait_event(std::min(wait, std::chrono::milliseconds(100)))) {
            if (e->kind == plc::PlcEvent::Kind::kReset) {
                pending.reset();
            } else if (e->trigger.recipe_slot != 1) {
                s.fault(static_cast<std::uint16_t>(plc::ErrorCode::kUnknownRecipe));
            } else {
                pending = e->trigger;
                due = Clock::now() + std::chrono::milliseconds(a.busy_ms);
                scanned = Clock::now() + std::chrono::milliseconds(a.busy_ms / 2);
                scans_reported = false;
            }
        }
        if (pending && !scans_reported && Clock::now() >= scanned) {
            s.scans_done(pending->trigger_id);
            scans_reported = true;
        }
        if (pending && Clock::now() >= due) {
            if (pending->part_id == kFaultPart)
                s.fault(static_cast<std::uint16_t>(plc::ErrorCode::kMeasurementFailed));
            else if (auto ok = s.finish(pending->trigger_id,
                                        demo_result(*recipe, pending->part_id, revision));
                     ok)
                spdlog::info("part {}: DONE", pending->part_id);
            pending.reset();
        }
    }
    const auto st = s.stats();
    spdlog::info(
        "stopping: {} connections ({} refused, {} timed out, {} malformed), {} requests, "
        "{} exceptions",
        st.accepted, st.refused, st.timed_out, st.malformed, st.requests, st.exceptions);
    return 0;
}

// ---- plc pyrometer / pyrometer-sim -----------------------------------------------------------

struct PyroArgs {
    std::string config = HOTGAUGE_CONFIG_DIR "/plc.yaml";
    std::optional<std::string> device;
    std::optional<int> baud, slave, reg;
    std::optional<double> scale;
    int count = 1;
    double temperature = 1050.0;
};

// The pyrometer section of the config file, with the command line's overrides.
core::Result<plc::PyrometerConfig> pyrometer_config(const PyroArgs& a) {
    auto file = read_plc_config(a.config);
    if (!file) return file.error();
    auto c = file->pyrometer;
    if (a.device) c.serial.device = *a.device;
    if (a.baud) c.serial.baud = *a.baud;
    if (a.slave) c.serial.slave_id = *a.slave;
    if (a.reg) c.register_address = *a.reg;
    if (a.scale) c.scale = *a.scale;
    return c;
}

int pyrometer(const PyroArgs& a) {
    auto cfg = pyrometer_config(a);
    if (!cfg) {
        spdlog::error("{}", cfg.error().message);
        return 1;
    }
    const auto& c = *cfg;
    auto p = plc::Pyrometer::start(c);
    if (!p) {
        spdlog::error("{}", p.error().message);
        return 1;
    }
    stop_on_signals();
    plc::PyrometerReading r;
    // One line per poll period after the first answer (or the stale time without one).
    for (int i = 0; !g_stop && (a.count <= 0 || i < a.count); ++i) {
        const auto deadline = Clock::now() + std::chrono::milliseconds(c.stale_after_ms);
        const auto before = (*p)->latest().reads + (*p)->latest().errors;
        do {
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
            r = (*p)->latest();
        } while (!g_stop && r.reads + r.errors == before && Clock::now() < deadline);
        if (r.temperature_c)
            std::printf(
                "%s: %.1f °C, %lld ms old%s%s%s\n", c.serial.device.c_str(), *r.temperature_c,
                static_cast<long long>(r.age_ms), r.stale ? ", STALE" : "",
                r.out_of_range ? ", OUT OF RANGE" : "",
                r.last_error.empty() ? "" : (", last read failed: " + r.last_error).c_str());
        else
            std::printf("%s: no reading (%s)\n", c.serial.device.c_str(),
                        r.last_error.empty() ? "no answer yet" : r.last_error.c_str());
        std::fflush(stdout);
    }
    return r.valid() ? 0 : 1;
}

int pyrometer_sim(const PyroArgs& a) {
    auto cfg = pyrometer_config(a);
    if (!cfg) {
        spdlog::error("{}", cfg.error().message);
        return 1;
    }
    const auto& c = *cfg;
    auto sim = plc::PyrometerSimulator::start(c.serial, c.register_address, c.scale);
    if (!sim) {
        spdlog::error("{}", sim.error().message);
        return 1;
    }
    (*sim)->set_temperature(a.temperature);
    stop_on_signals();
    std::printf("simulated pyrometer on %s (slave %d, register %d): %.1f °C\n",
                c.serial.device.c_str(), c.serial.slave_id, c.register_address, a.temperature);
    std::fflush(stdout);
    while (!g_stop) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    return 0;
}

// ---- plc map ---------------------------------------------------------------------------------

int print_map() {
    std::fputs(plc::map_markdown().c_str(), stdout);
    return 0;
}

// Which feature of the recipe is in which slot, where its registers are, what it is judged
// against, and the revision the PLC reads at input 118 with every result of it.
int print_recipe_map(const std::string& file) {
    auto recipe = io::read_recipe(file);
    if (!recipe) {
        spdlog::error("{}", recipe.error().message);
        return 1;
    }
    // What the daemon refuses at load (the faces it scans are in its config: --check-config).
    if (auto ok = cell::check_recipe_for_cell(*recipe, file, nullptr); !ok) {
        spdlog::error("{}", ok.error().message);
        return 1;
    }
    std::printf("Recipe %s (%s): revision %u (input 118 of its results)\n\n", recipe->name.c_str(),
                file.c_str(), static_cast<unsigned>(cell::recipe_revision(file)));
    std::printf(
        "| Slot | Feature | Input (0-based): µm / mm / verdict / drift and reasons | 3xxxx first | "
        "Nominal mm | Lower limit mm | Upper limit mm |\n| --- | --- | --- | --- | --- | --- | --- "
        "|\n");
    auto features = recipe->features;
    std::sort(features.begin(), features.end(),
              [](const auto& a, const auto& b) { return a.slot < b.slot; });
    for (const auto& f : features) {
        const unsigned a = plc::ir::feature(f.slot);
        std::printf("| %d | %s | %u–%u / %u–%u / %u / %u | %u | %.3f | %.3f | %.3f |\n", f.slot,
                    f.name.c_str(), a, a + 1, a + 2, a + 3, a + 4, a + 5, 30001u + a, f.nominal_mm,
                    f.nominal_mm + f.tol_lower_mm, f.nominal_mm + f.tol_upper_mm);
    }
    return 0;
}

}  // namespace

Command add_plc(CLI::App& app) {
    auto* plc = app.add_subcommand("plc",
                                   "PLC interface: Modbus TCP server, register map, "
                                   "pyrometer (docs/plc-modbus.md)");
    plc->require_subcommand(1);

    auto sa = std::make_shared<ServeArgs>();
    auto* s = plc->add_subcommand("serve", "Modbus TCP server with a scripted stand-in cell");
    s->add_option("--config", sa->config, "PLC config (server section)")->capture_default_str();
    s->add_option("--bind", sa->bind, "bind address (overrides the config)");
    s->add_option("--port", sa->port, "TCP port, 0: ephemeral (overrides the config)");
    s->add_option("--port-file", sa->port_file, "write the bound port to this file");
    s->add_option("--word-order", sa->word_order, "32-bit word order (overrides the config)")
        ->check(CLI::IsMember({"big", "little"}));
    s->add_option("--max-connections", sa->max_connections, "overrides the config");
    s->add_option("--idle-timeout-ms", sa->idle_timeout_ms, "overrides the config");
    s->add_option("--recipe", sa->recipe, "recipe of slot 1 (demo results: its nominal values)")
        ->capture_default_str();
    s->add_option("--busy-ms", sa->busy_ms, "stand-in measuring time per part")
        ->capture_default_str();
    s->add_option("--duration-s", sa->duration_s, "stop after this long (0: at SIGINT/SIGTERM)")
        ->capture_default_str();

    auto* m = plc->add_subcommand("map", "print the register map tables (as in the docs)");
    auto map_recipe = std::make_shared<std::string>();
    m->add_option("--recipe", *map_recipe,
                  "print instead which feature of this recipe is in which slot, and its revision");

    auto pa = std::make_shared<PyroArgs>();
    auto* p = plc->add_subcommand("pyrometer", "read the pyrometer (Modbus RTU) and print");
    auto* ps = plc->add_subcommand("pyrometer-sim", "simulated pyrometer on a serial device");
    for (auto* sub : {p, ps}) {
        sub->add_option("--config", pa->config, "PLC config (pyrometer section)")
            ->capture_default_str();
        sub->add_option("--device", pa->device, "serial device (overrides the config)");
        sub->add_option("--baud", pa->baud, "baud rate (overrides the config)");
        sub->add_option("--slave", pa->slave, "Modbus slave id (overrides the config)");
        sub->add_option("--register", pa->reg, "0-based register (overrides the config)");
        sub->add_option("--scale", pa->scale, "°C per count (overrides the config)");
    }
    p->add_option("--count", pa->count, "readings to print, 0: until SIGINT")
        ->capture_default_str();
    ps->add_option("--temperature", pa->temperature, "temperature to serve, °C")
        ->capture_default_str();

    return [=] {
        if (s->parsed()) return serve(*sa);
        if (m->parsed()) return map_recipe->empty() ? print_map() : print_recipe_map(*map_recipe);
        if (p->parsed()) return pyrometer(*pa);
        if (ps->parsed()) return pyrometer_sim(*pa);
        return 2;
    };
}

}  // namespace hotgauge::app
