// Pyrometer over Modbus RTU (docs/plc-modbus.md "Pyrometer"): libmodbus master and slave.
#include "hotgauge/plc/pyrometer.hpp"

#include <modbus/modbus.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "log.hpp"

namespace hotgauge::plc {
namespace {

using Clock = std::chrono::steady_clock;
using detail::log;

// A libmodbus RTU context on `serial`, connected; errors name the device.
core::Result<modbus_t*> open_rtu(const SerialConfig& s, const char* who) {
    const std::string where = std::string(who) + ": " + s.device + ": ";
    modbus_t* ctx = modbus_new_rtu(s.device.c_str(), s.baud, s.parity, s.data_bits, s.stop_bits);
    if (!ctx) return core::make_error(where + modbus_strerror(errno));
    if (modbus_set_slave(ctx, s.slave_id) != 0) {
        const int e = errno;
        modbus_free(ctx);
        return core::make_error(where + "slave id " + std::to_string(s.slave_id) + ": " +
                                modbus_strerror(e));
    }
    if (modbus_connect(ctx) != 0) {
        const int e = errno;
        modbus_free(ctx);
        return core::make_error(where + modbus_strerror(e));
    }
    return ctx;
}

void set_timeout(modbus_t* ctx, int ms, int (*setter)(modbus_t*, std::uint32_t, std::uint32_t)) {
    setter(ctx, static_cast<std::uint32_t>(ms / 1000),
           static_cast<std::uint32_t>(ms % 1000) * 1000);
}

core::Result<void> check_serial(const SerialConfig& s) {
    if (s.device.empty()) return core::make_error("pyrometer: no serial device");
    if (s.baud <= 0) return core::make_error("pyrometer: baud must be positive");
    if (s.parity != 'N' && s.parity != 'E' && s.parity != 'O')
        return core::make_error("pyrometer: parity must be none, even or odd");
    if (s.data_bits < 5 || s.data_bits > 8)
        return core::make_error("pyrometer: data_bits must be 5..8");
    if (s.stop_bits != 1 && s.stop_bits != 2)
        return core::make_error("pyrometer: stop_bits must be 1 or 2");
    if (s.slave_id < 1 || s.slave_id > 247)
        return core::make_error("pyrometer: slave_id must be 1..247");
    return {};
}

}  // namespace

core::Result<void> check_config(const PyrometerConfig& c) {
    if (auto ok = check_serial(c.serial); !ok) return ok;
    if (c.register_address < 0 || c.register_address > 65535)
        return core::make_error("pyrometer: register outside 0..65535");
    if (!(c.scale != 0.0) || !std::isfinite(c.scale))
        return core::make_error("pyrometer: scale must be non-zero");
    if (c.poll_period_ms < 10) return core::make_error("pyrometer: poll_period_ms must be >= 10");
    if (c.response_timeout_ms < 1)
        return core::make_error("pyrometer: response_timeout_ms must be >= 1");
    if (c.stale_after_ms < c.poll_period_ms)
        return core::make_error("pyrometer: stale_after_ms must be at least poll_period_ms");
    if (!(c.min_valid_c < c.max_valid_c))
        return core::make_error("pyrometer: min_valid_c must be below max_valid_c");
    return {};
}

struct Pyrometer::Impl {
    PyrometerConfig config;
    modbus_t* ctx = nullptr;
    std::thread thread;
    std::mutex mutex;  // guards the reading fields and `stopping`
    std::condition_variable wake;
    bool stopping = false;
    std::optional<double> value_c;
    Clock::time_point read_at;
    std::uint64_t reads = 0, errors = 0;
    std::string last_error;

    ~Impl() {
        {
            std::lock_guard lock(mutex);
            stopping = true;
        }
        wake.notify_all();
        if (thread.joinable()) thread.join();
        if (ctx) {
            modbus_close(ctx);
            modbus_free(ctx);
        }
    }

    void run() {
        const auto period = std::chrono::milliseconds(config.poll_period_ms);
        bool connected = true;  // start() connected
        bool failing = false;   // in a streak of failures (logged once)
        auto next = Clock::now();
        for (;;) {
            std::string error;
            std::optional<double> value;
            if (!connected && modbus_connect(ctx) == 0) connected = true;
            if (connected) {
                std::uint16_t raw = 0;
                const int rc =
                    config.input_register
                        ? modbus_read_input_registers(ctx, config.register_address, 1, &raw)
                        : modbus_read_registers(ctx, config.register_address, 1, &raw);
                if (rc == 1) {
                    const double counts = config.signed_value
                                              ? static_cast<double>(static_cast<std::int16_t>(raw))
                                              : static_cast<double>(raw);
                    value = counts * config.scale + config.offset_c;
                } else {
                    const int e = errno;
                    error = modbus_strerror(e);
                    modbus_flush(ctx);
                    if (e == EBADF || e == EIO || e == ENXIO || e == ENODEV) {
                        modbus_close(ctx);  // the device went away: reopen next time
                        connected = false;
                    }
                }
            } else {
                error = std::string("cannot reopen: ") + modbus_strerror(errno);
            }
            if (!error.empty() && !failing)
                log().warn("pyrometer {}: {} (logged once until it reads again)",
                           config.serial.device, error);
            if (error.empty() && failing)
                log().info("pyrometer {}: reading again", config.serial.device);
            failing = !error.empty();
            std::unique_lock lock(mutex);
            if (value) {
                value_c = value;
                read_at = Clock::now();
                ++reads;
                last_error.clear();
            } else {
                ++errors;
                last_error = error;
            }
            next += period;
            if (next < Clock::now()) next = Clock::now();  // a slow read: no burst after it
            if (wake.wait_until(lock, next, [&] { return stopping; })) return;
        }
    }
};

Pyrometer::Pyrometer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Pyrometer::~Pyrometer() = default;

core::Result<std::unique_ptr<Pyrometer>> Pyrometer::start(const PyrometerConfig& config) {
    if (auto ok = check_config(config); !ok) return ok.error();
    auto ctx = open_rtu(config.serial, "pyrometer");
    if (!ctx) return ctx.error();
    auto impl = std::make_unique<Impl>();
    impl->config = config;
    impl->ctx = *ctx;
    set_timeout(impl->ctx, config.response_timeout_ms, modbus_set_response_timeout);
    Impl* raw = impl.get();
    impl->thread = std::thread([raw] { raw->run(); });
    log().info("pyrometer on {} ({} baud, parity {}, slave {}, register {}, every {} ms)",
               config.serial.device, config.serial.baud, config.serial.parity,
               config.serial.slave_id, config.register_address, config.poll_period_ms);
    return std::unique_ptr<Pyrometer>(new Pyrometer(std::move(impl)));
}

PyrometerReading Pyrometer::latest() const {
    std::lock_guard lock(impl_->mutex);
    const auto& c = impl_->config;
    PyrometerReading r;
    r.temperature_c = impl_->value_c;
    r.reads = impl_->reads;
    r.errors = impl_->errors;
    r.last_error = impl_->last_error;
    if (r.temperature_c) {
        r.age_ms =
            std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - impl_->read_at)
                .count();
        r.stale = r.age_ms > c.stale_after_ms;
        r.out_of_range = *r.temperature_c < c.min_valid_c || *r.temperature_c > c.max_valid_c;
    }
    return r;
}

PyrometerReading Pyrometer::wait_valid(std::chrono::milliseconds within) const {
    const auto until = Clock::now() + within;
    PyrometerReading r = latest();
    while (!r.valid() && Clock::now() < until) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
        r = latest();
    }
    return r;
}

struct PyrometerSimulator::Impl {
    modbus_t* ctx = nullptr;
    modbus_mapping_t* mapping = nullptr;
    int address = 0;
    double scale = 0.1;
    std::thread thread;
    std::atomic<bool> stopping{false};
    std::atomic<std::uint16_t> raw{0};
    std::atomic<bool> responding{true};
    std::atomic<std::uint64_t> served{0};

    ~Impl() {
        stopping = true;
        if (thread.joinable()) thread.join();
        if (mapping) modbus_mapping_free(mapping);
        if (ctx) {
            modbus_close(ctx);
            modbus_free(ctx);
        }
    }

    void run() {
        std::uint8_t request[MODBUS_RTU_MAX_ADU_LENGTH];
        while (!stopping) {
            const int rc = modbus_receive(ctx, request);  // returns after the indication timeout
            if (rc <= 0) {  // 0: for another slave; -1: timeout, bad CRC, ...
                if (rc < 0 && errno != ETIMEDOUT) modbus_flush(ctx);
                continue;
            }
            if (!responding) continue;
            mapping->tab_registers[address] = raw;
            mapping->tab_input_registers[address] = raw;
            if (modbus_reply(ctx, request, rc, mapping) > 0) ++served;
        }
    }
};

PyrometerSimulator::PyrometerSimulator(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
PyrometerSimulator::~PyrometerSimulator() = default;

core::Result<std::unique_ptr<PyrometerSimulator>> PyrometerSimulator::start(
    const SerialConfig& serial, int register_address, double scale) {
    if (auto ok = check_serial(serial); !ok) return ok.error();
    if (register_address < 0 || register_address > 1000 || !(scale != 0.0))
        return core::make_error("pyrometer simulator: register must be 0..1000, scale non-zero");
    auto ctx = open_rtu(serial, "pyrometer simulator");
    if (!ctx) return ctx.error();
    auto impl = std::make_unique<Impl>();
    impl->ctx = *ctx;
    impl->address = register_address;
    impl->scale = scale;
    impl->mapping = modbus_mapping_new(0, 0, register_address + 1, register_address + 1);
    if (!impl->mapping) return core::make_error("pyrometer simulator: out of memory");
    set_timeout(impl->ctx, 50, modbus_set_indication_timeout);
    Impl* raw = impl.get();
    impl->thread = std::thread([raw] { raw->run(); });
    return std::unique_ptr<PyrometerSimulator>(new PyrometerSimulator(std::move(impl)));
}

void PyrometerSimulator::set_temperature(double temperature_c) {
    const double counts = std::round(temperature_c / impl_->scale);
    const double clamped = std::clamp(counts, -32768.0, 32767.0);
    impl_->raw = static_cast<std::uint16_t>(static_cast<std::int16_t>(clamped));
}

void PyrometerSimulator::set_responding(bool responding) { impl_->responding = responding; }

std::uint64_t PyrometerSimulator::served() const { return impl_->served; }

}  // namespace hotgauge::plc
