#pragma once
// The virtual cell's robot/axis controller (docs/virtual-cell.md "Faces and the axis"): the
// sensor is moved from face to face on command over Modbus TCP, as line integrators drive an axis
// or robot controller. The virtual camera and accelerometer follow the face the axis is at.
//
// Holding registers (0-based):
//   0  target face: 1..N in the cell config's face order          (write)
//   1  command: 1 = move to the target; reads back 0 once taken    (write)
//   2  current face: 1..N, 0 while moving                          (read)
//   3  state: 0 in position, 1 moving, 2 fault (bad target)        (read)
//   4  number of faces N                                           (read)
//   5  moves completed (wraps at 65536)                            (read)
//   6  part request: N >= 1 = load part N onto the support;         (write)
//      reads back 0 once taken
//   7  part loaded: the part on the support, as the owner reports   (read)
//      it with set_part_loaded(); 0 from the moment a request is
//      taken until the owner reports the new part loaded
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "hotgauge/core/result.hpp"

namespace hotgauge::vcell {

struct AxisServerConfig {
    std::string bind = "127.0.0.1";
    int port = 0;  // 0 = an ephemeral port, see port()
    int n_faces = 4;
    int initial_face = 1;
    double move_time_s = 0.3;  // the robot's move between faces
};

// Thread safety: current_face() and set_part_loaded() from any thread; on_arrival and
// on_part_request run on the server thread and must return quickly (the server answers no client
// meanwhile).
class AxisServer {
  public:
    static core::Result<std::unique_ptr<AxisServer>> start(
        const AxisServerConfig& config, std::function<void(int face)> on_arrival,
        std::function<void(int part)> on_part_request = {});
    ~AxisServer();
    AxisServer(const AxisServer&) = delete;
    AxisServer& operator=(const AxisServer&) = delete;

    int port() const;
    int current_face() const;        // 1..N; 0 while moving
    void set_part_loaded(int part);  // register 7; clients read it from their next request on

  private:
    struct Impl;
    explicit AxisServer(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hotgauge::vcell
