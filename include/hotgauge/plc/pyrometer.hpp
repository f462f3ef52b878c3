#pragma once
// The part pyrometer (Keens FT-H40K class) over Modbus RTU, and a simulated one for tests and the
// virtual cell (docs/plc-modbus.md "Pyrometer").
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "hotgauge/core/result.hpp"

namespace hotgauge::plc {

struct SerialConfig {
    std::string device = "/dev/ttyUSB0";
    int baud = 9600;
    char parity = 'N';  // 'N', 'E' or 'O'
    int data_bits = 8;
    int stop_bits = 1;
    int slave_id = 1;
};

struct PyrometerConfig {
    SerialConfig serial;
    int register_address = 0;     // 0-based PDU address of the temperature register
    bool input_register = false;  // function 04 instead of 03
    bool signed_value = true;     // the register is int16 (else uint16)
    double scale = 0.1;           // °C per count
    double offset_c = 0.0;        // added after scaling
    int poll_period_ms = 100;
    int response_timeout_ms = 200;
    int stale_after_ms = 1000;    // no good read for this long: the reading is stale
    double min_valid_c = 300.0;   // outside [min, max]: out of range (sensor below its span,
    double max_valid_c = 1600.0;  // no part in view, or a broken sensor)
};

core::Result<void> check_config(const PyrometerConfig& c);

struct PyrometerReading {
    std::optional<double> temperature_c;  // last value read, if any was
    std::int64_t age_ms = -1;             // since that read; -1 if none
    bool stale = true;                    // no read within stale_after_ms
    bool out_of_range = false;            // the last value lies outside [min_valid, max_valid]
    std::uint64_t reads = 0, errors = 0;
    std::string last_error;  // of the most recent failed read; "" if the last read succeeded
    bool valid() const { return temperature_c && !stale && !out_of_range; }
};

// Modbus RTU master polling the temperature register on its own thread.
// Thread-safety: latest() may be called from any thread; the poller holds the lock only to
// store a reading, never across serial I/O.
class Pyrometer {
  public:
    // Opens the serial device (a start-up failure names it) and starts polling.
    static core::Result<std::unique_ptr<Pyrometer>> start(const PyrometerConfig& config);
    ~Pyrometer();
    Pyrometer(const Pyrometer&) = delete;
    Pyrometer& operator=(const Pyrometer&) = delete;

    PyrometerReading latest() const;
    // The latest reading once it is valid, waiting at most `within` for the poller to get one
    // (a sensor that missed a few polls); the latest reading, invalid, when it does not.
    PyrometerReading wait_valid(std::chrono::milliseconds within) const;

  private:
    struct Impl;
    explicit Pyrometer(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

// A pyrometer stand-in: a Modbus RTU slave on a serial device serving one temperature
// register (holding and input alike) at `register_address`, scaled like the real one.
// Thread-safety: the setters may be called from any thread.
class PyrometerSimulator {
  public:
    static core::Result<std::unique_ptr<PyrometerSimulator>> start(const SerialConfig& serial,
                                                                   int register_address = 0,
                                                                   double scale = 0.1);
    ~PyrometerSimulator();
    PyrometerSimulator(const PyrometerSimulator&) = delete;
    PyrometerSimulator& operator=(const PyrometerSimulator&) = delete;

    void set_temperature(double temperature_c);
    void set_responding(bool responding);  // false: a dead sensor, requests go unanswered
    std::uint64_t served() const;          // requests answered

  private:
    struct Impl;
    explicit PyrometerSimulator(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hotgauge::plc
