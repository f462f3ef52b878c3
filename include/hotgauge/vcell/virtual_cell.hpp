#pragma once
// The virtual inspection cell (docs/virtual-cell.md): the simulated hub-a on its support, a
// virtual GigE Vision laser camera rendering the face being scanned frame by frame, and the
// accelerometer in the sensor head streaming HGA1 datagrams over UDP, all on one clock
// (CLOCK_REALTIME), with the press vibration applied at each frame's and sample's time.
//
// Scan motion is a constant-velocity axis: from the first frame after AcquisitionStart, the
// sensor travels speed_mm_s along the face's scan direction, so profile k of an acquisition is
// at speed · (t_k − t_0) times the face's true travel_scale; acquire::ScanBuilder takes it as
// speed · (t_k − t_0) times the calibrated one. Peaks frames bundle
// profiles_per_frame = Height / rows_per_profile profiles, line_period_s apart.
//
// The conveyor (docs/virtual-cell.md "Parts"): a PLC loads part N (1, 2, ...) onto the support by
// writing the axis controller's register 6; part_options() says which part that is. The part is
// built on a loader thread and then swapped in whole: the camera renders the old part until the
// new one is complete, never a mix. Part 1 is `part` itself and is loaded at start.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>

#include "hotgauge/acquire/stripe.hpp"
#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/core/part.hpp"
#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/plc/pyrometer.hpp"
#include "hotgauge/sim/simulator.hpp"
#include "hotgauge/vcell/axis_server.hpp"
#include "hotgauge/vcell/gv_device.hpp"
#include "hotgauge/vcell/render.hpp"
#include "hotgauge/vcell/replay.hpp"

namespace hotgauge::vcell {

// A recording served instead of simulated parts (docs/virtual-cell.md "Replay"): the camera sends
// each face's recorded profiles as peak frames, the accelerometer its record, the pyrometer its
// temperature, all shifted to now; the axis and the conveyor work as usual.
struct ReplayConfig {
    std::filesystem::path dir;       // for messages
    core::Recording recording;       // moved into the cell at start
    calib::Calibration calibration;  // the receiver's: its triangulation and clock offset
    double scan_s = 1.3;             // the receiver's scan length (hotgauged camera.scan_s)
};

struct VirtualCellConfig {
    core::Recipe recipe;
    sim::CellConfig cell;
    sim::SimOptions part;  // seed, temperature, pose: part 1, and the base of parts 2, 3, ...
    std::string face = "top";
    std::string mode = "image";  // image | peaks
    double speed_mm_s = 100.0;
    double line_period_s = 1e-3;  // peaks: time between the profiles of one frame
    acquire::PeakFormat peaks;
    int peak_row_offset =
        0;  // peaks: first sensor row of the camera's window (its peak rows start there)
    StripeLook look;
    GvDeviceConfig device;
    std::string accel_to;  // HOST:PORT of the daemon's accelerometer receiver; "" = none
    std::uint16_t accel_sensor_id = 0;
    double accel_datagram_s = 0.01;  // samples per datagram: rate × this
    // The robot/axis controller (axis_server.hpp): Modbus TCP; port 0 = ephemeral, −1 = none
    // (the sensor stays at `face`).
    int axis_port = -1;
    std::string axis_bind = "127.0.0.1";
    double axis_move_s = 0.3;
    // Non-empty: each part's ground truth goes to truth_dir/part-NNNN (sim::write_truth) before
    // the part is reported loaded, so a reader who sees register 7 == N finds it complete.
    std::filesystem::path truth_dir;
    // Set: a pyrometer stand-in on this serial device (register 0, 0.1 °C per count) reads the
    // temperature of the part on the support.
    std::optional<plc::SerialConfig> pyrometer;
    // Conveyor parts that are the cold master (docs/virtual-cell.md "The master"): the same
    // physical part each time, `master.seed`'s dimensions and pose at `master.temperature_c`
    // (20 °C: below the pyrometer's span, so it reads nothing, as on a real cell).
    std::set<int> master_parts;
    sim::SimOptions master;
    // Bad conveyor parts (docs/virtual-cell.md "Parts"): part N -> features moved out of
    // tolerance (name -> mm, as sim::SimOptions::bad_mm), added to `part.bad_mm`. A master part
    // is never bad.
    std::map<int, std::map<std::string, double>> bad_parts;
    std::optional<ReplayConfig> replay;  // set: replay it (peaks mode), no part is simulated
};

// Part n (≥ 1) of the conveyor: `base` with seed + (n − 1) and temperature + d(n), where
// d(n) = ((n − 1)·37 + 100) mod 201 − 100 °C. So d(1) = 0 (part 1 is `base`), and any 201
// consecutive parts take each offset in −100..100 °C once (37 and 201 are coprime):
// 0, +37, +74, −90, −53, −16, +21, +58, +95, −69, −32, +5 for parts 1..12.
sim::SimOptions part_options(const sim::SimOptions& base, int n);

// What conveyor part n is: the master when n is one of `c.master_parts`, else part_options with
// the part's `c.bad_parts`.
sim::SimOptions conveyor_options(const VirtualCellConfig& c, int n);

struct VirtualCellStats {
    GvDeviceStats camera;
    std::uint64_t accel_datagrams = 0, accel_samples = 0, accel_send_errors = 0;
    std::uint64_t acquisitions = 0;
};

// Thread safety: every accessor from any thread.
class VirtualCell {
  public:
    // Builds part 1 and the device, then serves until destroyed. Errors name the setting.
    static core::Result<std::unique_ptr<VirtualCell>> start(VirtualCellConfig config);
    ~VirtualCell();
    VirtualCell(const VirtualCell&) = delete;
    VirtualCell& operator=(const VirtualCell&) = delete;

    // The part on the support, the one the camera renders: while part N loads it is still the
    // previous one, while part_loaded() reads 0 as register 7 does.
    sim::SimTruth truth() const;  // a copy: the part may be swapped meanwhile (replay: none)
    double part_temperature_c() const;
    int part_loaded() const;  // register 7: 1 at start; 0 while a part loads (or failed to)
    int axis_port() const;    // −1 without an axis
    VirtualCellStats stats() const;
    EncodeStats replay_stats() const;  // replay: how exactly the profiles went out as peaks

  private:
    struct Impl;
    explicit VirtualCell(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hotgauge::vcell
