#pragma once
// The cell's devices as the daemon sees them, updated continuously in every state (while idle
// too): the PLC's device-health register (docs/plc-modbus.md "Device health"), the status page
// and the journal read the same snapshot.
#include <array>
#include <cstdint>
#include <string>

namespace hotgauge::cell {

// kPlantLink: the MQTT broker and the spool (docs/plant-data.md): not working while the broker
// cannot be reached (results wait in the spool) or the spool refuses results.
enum class Device : int {
    kCamera = 0,
    kAccelerometer,
    kPyrometer,
    kAxis,
    kResultsDisk,
    kPlantLink
};
inline constexpr int kDeviceCount = 6;
const char* to_string(Device d);  // "camera", "accelerometer", ...

struct DeviceStatus {
    bool configured = false;  // not configured (no pyrometer, axis "none"): never a fault
    bool ok = false;          // configured and working
    std::string detail;       // what is wrong, or what it is doing ("2000 Hz, last sample 3 ms")
};

struct DeviceHealth {
    std::array<DeviceStatus, kDeviceCount> devices;
    std::int64_t updated_ns = 0;  // CLOCK_REALTIME of the last update

    const DeviceStatus& operator[](Device d) const { return devices[static_cast<int>(d)]; }
    DeviceStatus& operator[](Device d) { return devices[static_cast<int>(d)]; }
    // The PLC's bit word: bit d set when device d is configured and not ok.
    std::uint16_t fault_bits() const {
        std::uint16_t bits = 0;
        for (int d = 0; d < kDeviceCount; ++d)
            if (devices[d].configured && !devices[d].ok)
                bits |= static_cast<std::uint16_t>(1u << d);
        return bits;
    }
};

}  // namespace hotgauge::cell
