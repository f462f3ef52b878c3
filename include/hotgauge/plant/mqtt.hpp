#pragma once
// The cell's data to the plant's MQTT broker (docs/plant-data.md), through libmosquitto:
//   hotgauge/<site>/<cell>/result   every result: the results file's JSON line, QoS 1, in order,
//                                   from the disk spool (nothing lost, nothing acknowledged twice)
//   hotgauge/<site>/<cell>/state    the daemon's state, retained, QoS 1; the last will is
//                                   {"state":"offline"} there, retained
//   hotgauge/<site>/<cell>/health   the devices' health, retained, QoS 1
// One thread of its own talks to the broker; the cell only appends to the spool and sets the
// latest state and health, so no cycle ever waits for the broker. A broker that cannot be
// reached, refuses the password or fails the TLS handshake is logged with the reason and tried
// again with a growing delay (retry_min_s doubling up to retry_max_s); measuring goes on.
// One result is in flight at a time: the next is sent when the broker has acknowledged it
// (PUBACK), so the order on the broker is the spool's order.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "hotgauge/core/result.hpp"
#include "hotgauge/plant/spool.hpp"

namespace hotgauge::plant {

struct MqttTls {
    std::filesystem::path ca_file;    // set: TLS on, the broker's certificate checked against it
    std::filesystem::path cert_file;  // optional client certificate and its key
    std::filesystem::path key_file;
};

struct MqttConfig {
    bool enabled = false;
    std::string host = "127.0.0.1";
    int port = 1883;
    std::string site;  // topic levels: hotgauge/<site>/<cell>/...
    std::string cell;
    std::string client_id;                // "" -> "hotgauge-<site>-<cell>"
    std::string username;                 // "" -> none
    std::filesystem::path password_file;  // the password, alone in a file (not in the config)
    MqttTls tls;
    int keepalive_s = 30;
    double retry_min_s = 1.0;
    double retry_max_s = 60.0;
    SpoolConfig spool;
};

// A site or cell name as a topic level: not empty, without MQTT's separator or wildcards (§4.7).
bool valid_topic_level(std::string_view level);

// What the publisher is doing: health, metrics, the status page.
struct PublisherStatus {
    bool connected = false;
    std::string problem;          // why it is not connected (the last failure), "" when connected
    std::uint64_t attempts = 0;   // connection attempts that failed since the last success
    double retry_in_s = 0;        // the current backoff delay
    std::uint64_t published = 0;  // results acknowledged by the broker since start
    std::uint64_t connects = 0;   // successful connections since start
    SpoolState spool;
};

class Publisher {
  public:
    // Opens the spool and starts the thread; the first connection is made there. An error only
    // for what cannot be retried (the spool's folder, a TLS file that cannot be read, a
    // password file that is missing), naming the file.
    static core::Result<std::unique_ptr<Publisher>> start(const MqttConfig& config);
    // Stops the thread within about a second: it never waits for the broker to come back;
    // spooled results stay for the next start. When connected, the state is set to the last
    // will's {"state":"offline"} first (a clean DISCONNECT sends no will).
    ~Publisher();
    Publisher(const Publisher&) = delete;
    Publisher& operator=(const Publisher&) = delete;

    // A result's JSON line into the spool (durable when it returns); refused when the spool is
    // full or cannot be written, with the reason.
    core::Result<void> result(std::string_view json_line);
    // The newest result line ever put in the spool (Spool::last_appended).
    std::optional<std::string> last_result() const;
    core::Result<void> start_after(std::string_view json_line);  // Spool::start_after
    // The latest state and health (JSON objects): sent retained when they change and again
    // after every reconnection; only the newest matters, so they are not spooled.
    void state(std::string json);
    void health(std::string json);

    PublisherStatus status() const;
    std::string topic(std::string_view leaf) const;  // "hotgauge/<site>/<cell>/<leaf>"

  private:
    struct Impl;
    explicit Publisher(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hotgauge::plant
