#include "hotgauge/cell/health.hpp"

namespace hotgauge::cell {

const char* to_string(Device d) {
    switch (d) {
        case Device::kCamera:
            return "camera";
        case Device::kAccelerometer:
            return "accelerometer";
        case Device::kPyrometer:
            return "pyrometer";
        case Device::kAxis:
            return "axis";
        case Device::kResultsDisk:
            return "results disk";
        case Device::kPlantLink:
            return "plant link";
    }
    return "?";
}

}  // namespace hotgauge::cell
