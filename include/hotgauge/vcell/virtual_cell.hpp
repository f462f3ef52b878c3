#pragma once
// The virtual inspection cell (docs/virtual-cell.md): the simulated hub-a on its support, a
// virtual GigE Vision laser camera rendering the face being scanned frame by frame, and the
// accelerometer in the sensor head streaming HGA1 datagrams over UDP, all on one clock
// (CLOCK_REALTIME), with the press vibration applied at each frame's and sample's time.
//
// Scan motion is a constant-velocity axis: from the first frame after AcquisitionStart, the
// sensor travels speed_mm_s along the face's scan direction, so profile k of an acquisition is
// at speed · (t_k − t_0), as acquire::ScanBuilder assumes. Peaks frames bundle
// profiles_per_frame = Height / rows_per_profile profiles, line_period_s apart.
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "hotgauge/acquire/stripe.hpp"
#include "hotgauge/core/part.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/sim/simulator.hpp"
#include "hotgauge/vcell/axis_server.hpp"
#include "hotgauge/vcell/gv_device.hpp"
#include "hotgauge/vcell/render.hpp"

namespace hotgauge::vcell {

struct VirtualCellConfig {
    core::Recipe recipe;
    sim::CellConfig cell;
    sim::SimOptions part;  // seed, temperature, pose: the part on the support
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
};

struct VirtualCellStats {
    GvDeviceStats camera;
    std::uint64_t accel_datagrams = 0, accel_samples = 0, accel_send_errors = 0;
    std::uint64_t acquisitions = 0;
};

class VirtualCell {
  public:
    // Builds the part and the device, then serves until destroyed. Errors name the setting.
    static core::Result<std::unique_ptr<VirtualCell>> start(VirtualCellConfig config);
    ~VirtualCell();
    VirtualCell(const VirtualCell&) = delete;
    VirtualCell& operator=(const VirtualCell&) = delete;

    const sim::SimTruth& truth() const;
    int axis_port() const;  // −1 without an axis
    VirtualCellStats stats() const;

  private:
    struct Impl;
    explicit VirtualCell(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hotgauge::vcell
