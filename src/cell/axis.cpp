#include "hotgauge/cell/axis.hpp"

#include <modbus.h>

#include <cerrno>
#include <thread>

#include "hotgauge/cell/config.hpp"

namespace hotgauge::cell {
namespace {

// vcell/axis_server.hpp's holding registers.
constexpr int kTarget = 0, kCommand = 1, kCurrent = 2, kState = 3;
constexpr std::uint16_t kMove = 1, kInPosition = 0, kFault = 2;
constexpr auto kPoll = std::chrono::milliseconds(10);

modbus_t* as_ctx(void* p) { return static_cast<modbus_t*>(p); }

}  // namespace

ModbusAxis::ModbusAxis(const AxisConfig& config)
    : unit_id_(config.unit_id), timeout_(config.timeout_ms) {
    const auto colon = config.address.rfind(':');
    host_ = config.address.substr(0, colon);
    port_ = colon == std::string::npos ? 502 : std::stoi(config.address.substr(colon + 1));
}

ModbusAxis::~ModbusAxis() { disconnect(); }

void ModbusAxis::disconnect() {
    if (!ctx_) return;
    modbus_close(as_ctx(ctx_));
    modbus_free(as_ctx(ctx_));
    ctx_ = nullptr;
}

core::Error ModbusAxis::fail(const std::string& why) {
    const std::string message =
        "axis controller " + host_ + ":" + std::to_string(port_) + ": " + why;
    disconnect();  // the next move starts from a fresh connection
    return core::make_error(message);
}

core::Result<void> ModbusAxis::connect() {
    if (ctx_) return {};
    modbus_t* ctx = modbus_new_tcp(host_.c_str(), port_);
    if (!ctx) return fail("out of memory");
    ctx_ = ctx;
    modbus_set_slave(ctx, unit_id_);
    modbus_set_response_timeout(ctx, 0, 500'000);
    if (modbus_connect(ctx) != 0) return fail(std::string("connect: ") + modbus_strerror(errno));
    return {};
}

core::Result<void> ModbusAxis::read_status(std::uint16_t (&regs)[4]) {
    const bool reused = ctx_ != nullptr;
    if (auto ok = connect(); !ok) return ok.error();
    if (modbus_read_registers(as_ctx(ctx_), kTarget, 4, regs) != 4) {
        // A connection kept from the last move may have died with a restarted controller:
        // one fresh connection before giving up.
        const std::string why = modbus_strerror(errno);
        disconnect();
        if (!reused) return fail("read: " + why);
        if (auto ok = connect(); !ok) return ok.error();
        if (modbus_read_registers(as_ctx(ctx_), kTarget, 4, regs) != 4)
            return fail(std::string("read: ") + modbus_strerror(errno));
    }
    return {};
}

core::Result<void> ModbusAxis::check() {
    std::uint16_t regs[4] = {};
    return read_status(regs);
}

core::Result<bool> ModbusAxis::move_to(int position) {
    timed_out_ = false;
    std::uint16_t regs[4] = {};
    if (auto ok = read_status(regs); !ok) return ok.error();
    modbus_t* ctx = as_ctx(ctx_);
    if (regs[kCurrent] == position && regs[kState] == kInPosition) return false;
    const std::uint16_t cmd[2] = {static_cast<std::uint16_t>(position), kMove};
    if (modbus_write_registers(ctx, kTarget, 2, cmd) != 2)
        return fail(std::string("write: ") + modbus_strerror(errno));
    const auto deadline = std::chrono::steady_clock::now() + timeout_;
    for (;;) {
        std::this_thread::sleep_for(kPoll);
        if (modbus_read_registers(ctx, kTarget, 4, regs) != 4)
            return fail(std::string("read: ") + modbus_strerror(errno));
        // The command register reads 0 once the controller has taken the move; until then the
        // "in position" it reports is the old one.
        if (regs[kState] == kFault)
            return fail("fault while moving to position " + std::to_string(position));
        if (regs[kCommand] == 0 && regs[kState] == kInPosition && regs[kCurrent] == position)
            return true;
        if (std::chrono::steady_clock::now() > deadline) {
            timed_out_ = true;
            return fail("not in position " + std::to_string(position) + " after " +
                        std::to_string(timeout_.count()) + " ms");
        }
    }
}

}  // namespace hotgauge::cell
