#pragma once
// The robot or axis controller that takes the sensor from face to face, as a Modbus TCP client
// (docs/operations.md "Axis"; the register map is vcell/axis_server.hpp's, which the virtual
// cell serves): write the target position, command a move, wait until the controller reports
// the target in position. A controller that faults, vanishes or takes longer than the timeout
// fails the move with the reason; the next move reconnects.
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "hotgauge/core/result.hpp"

namespace hotgauge::cell {

struct AxisConfig;

// Thread safety: one thread moves the axis.
class ModbusAxis {
  public:
    explicit ModbusAxis(const AxisConfig& config);
    ~ModbusAxis();
    ModbusAxis(const ModbusAxis&) = delete;
    ModbusAxis& operator=(const ModbusAxis&) = delete;

    // Moves to controller position `position` (1..N) and returns once it is there: true if it
    // moved, false if it was there already. Errors name the controller's address.
    core::Result<bool> move_to(int position);
    // Between parts: the controller answers a read of its registers (reconnecting if need be).
    core::Result<void> check();
    // Whether the last failed move failed by taking longer than the timeout (the controller
    // answered but the axis did not arrive).
    bool timed_out() const { return timed_out_; }

  private:
    core::Result<void> connect();
    void disconnect();
    core::Result<void> read_status(std::uint16_t (&regs)[4]);  // target .. state, one reconnect
    core::Error fail(const std::string& why);

    std::string host_;
    int port_ = 0;
    int unit_id_ = 1;
    std::chrono::milliseconds timeout_;
    void* ctx_ = nullptr;  // modbus_t, kept out of the header
    bool timed_out_ = false;
};

}  // namespace hotgauge::cell
