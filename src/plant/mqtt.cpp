#include "hotgauge/plant/mqtt.hpp"

#include <mosquitto.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/socket.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <thread>

#include "log.hpp"

namespace hotgauge::plant {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

using detail::log;

// Process-wide and not thread-safe in libmosquitto; never undone (mosquitto_lib_cleanup would
// pull OpenSSL from under another publisher).
void init_library() {
    static std::once_flag once;
    std::call_once(once, [] { mosquitto_lib_init(); });
}

Clock::duration seconds(double s) {
    return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

core::Result<void> check_readable(const fs::path& file, const char* what) {
    std::ifstream in(file);
    if (!in)
        return core::make_error(file.string() + ": cannot read the " + what + ": " +
                                std::strerror(errno));
    return {};
}

// The password alone in its file; the editor's trailing newline is not part of it.
core::Result<std::string> read_password(const fs::path& file) {
    std::ifstream in(file);
    if (!in)
        return core::make_error(file.string() +
                                ": cannot read the MQTT password file: " + std::strerror(errno));
    std::stringstream all;
    all << in.rdbuf();
    std::string password = all.str();
    while (!password.empty() && (password.back() == '\n' || password.back() == '\r'))
        password.pop_back();
    return password;
}

core::Result<void> validate(const MqttConfig& c) {
    if (!valid_topic_level(c.site) || !valid_topic_level(c.cell))
        return core::make_error("mqtt.site and mqtt.cell: must be set, without '/', '+' or '#'");
    if (c.port <= 0 || c.port > 65535) return core::make_error("mqtt.port: must be 1 to 65535");
    // libmosquitto refuses keepalives of 1 to 4 s (mosquitto__connect_init).
    if (c.keepalive_s < 5 || c.keepalive_s > 65535)
        return core::make_error("mqtt.keepalive_s: must be 5 to 65535");
    if (!(c.retry_min_s > 0) || c.retry_max_s < c.retry_min_s)
        return core::make_error("mqtt.retry_min_s, retry_max_s: need 0 < min <= max");
    if (c.tls.cert_file.empty() != c.tls.key_file.empty())
        return core::make_error("mqtt.tls.cert_file and key_file: one without the other");
    return {};
}

// The files start() can check once, so that a typo is a start-up error and not a retry loop.
core::Result<void> check_files(const MqttConfig& c) {
    if (!c.tls.ca_file.empty()) {
        if (auto ok = check_readable(c.tls.ca_file, "MQTT TLS CA file"); !ok) return ok;
        if (!c.tls.cert_file.empty()) {
            if (auto ok = check_readable(c.tls.cert_file, "MQTT TLS client certificate"); !ok)
                return ok;
            if (auto ok = check_readable(c.tls.key_file, "MQTT TLS client key"); !ok) return ok;
        }
    }
    return {};
}

// CONNACK return codes of MQTT 3.1.1 (§3.2.2.3), in words.
std::string connack_words(int rc) {
    switch (rc) {
        case 1:
            return "refused: unacceptable protocol version";
        case 2:
            return "refused: client identifier rejected";
        case 3:
            return "refused: server unavailable";
        case 4:
            return "refused: bad username or password";
        case 5:
            return "refused: not authorised";
        default:
            return "refused: CONNACK code " + std::to_string(rc);
    }
}

// The TCP state of a socket (TCP_ESTABLISHED, TCP_CLOSE, ...), -1 when unknown.
int tcp_state(int fd) {
    tcp_info info{};
    socklen_t len = sizeof info;
    if (fd < 0 || ::getsockopt(fd, IPPROTO_TCP, TCP_INFO, &info, &len) != 0) return -1;
    return info.tcpi_state;
}

const char* c_str_or_null(const fs::path& p) { return p.empty() ? nullptr : p.c_str(); }

}  // namespace

// Thread safety: callers touch only `mutex`-guarded members (latest state and health, the
// status) and the spool (its own mutex); everything below "the thread's own" is used by the
// publisher's thread alone, including every libmosquitto call after start().
struct Publisher::Impl {
    MqttConfig config;
    std::string client_id, password, will_payload;
    std::unique_ptr<Spool> spool;

    struct Latest {
        std::string json;
        bool dirty = false;
    };
    mutable std::mutex mutex;
    Latest state, health;
    PublisherStatus status;  // without .spool, filled in by status()

    std::atomic<bool> stop{false};
    std::thread thread;

    // The thread's own. A fresh client per connection attempt: libmosquitto 2.0 re-sends the
    // QoS 1 messages of a client's last connection by itself after CONNACK, and a result sent
    // again by us as well would arrive twice.
    mosquitto* mosq = nullptr;
    bool connected = false;
    std::optional<int> in_flight;  // the result's message id, until its PUBACK
    std::string refusal;           // this attempt's CONNACK refusal, in words
    std::string library_error;     // the library's last error or warning text, this attempt
    bool tcp_established = false;  // this attempt's TCP connection was seen up
    std::optional<Clock::time_point> tcp_closed_at;  // and then closed, during the handshake
    double delay_s = 0;                              // the next backoff delay
    Clock::time_point next_try{}, results_paused_until{};

    std::string topic(std::string_view leaf) const {
        return "hotgauge/" + config.site + "/" + config.cell + "/" + std::string(leaf);
    }
    std::string where() const { return config.host + ":" + std::to_string(config.port); }

    void run();
    void attempt();
    std::string configure();
    void drive();
    std::string handshake_problem();
    std::string reason(int rc, int err) const;
    void fail(const std::string& why);
    void on_connected();
    void publish_latest();
    void publish_next_result();
    void on_acknowledged(int mid);
    void shutdown();
};

void Publisher::Impl::run() {
    while (!stop) {
        if (mosq) {
            drive();
        } else if (Clock::now() >= next_try) {
            attempt();
        } else {
            // The backoff, in short steps so that the destructor is never kept waiting.
            const auto step =
                std::min<Clock::duration>(next_try - Clock::now(), std::chrono::milliseconds(100));
            std::this_thread::sleep_for(step);
        }
    }
    shutdown();
}

// The client's settings for one connection attempt; "" or what is wrong.
std::string Publisher::Impl::configure() {
    mosquitto_int_option(mosq, MOSQ_OPT_PROTOCOL_VERSION, MQTT_PROTOCOL_V311);
    mosquitto_connect_callback_set(mosq, [](mosquitto*, void* obj, int rc) {
        auto& self = *static_cast<Impl*>(obj);
        if (rc == 0)
            self.on_connected();
        else
            self.refusal = connack_words(rc);
    });
    mosquitto_publish_callback_set(mosq, [](mosquitto*, void* obj, int mid) {
        static_cast<Impl*>(obj)->on_acknowledged(mid);
    });
    mosquitto_log_callback_set(mosq, [](mosquitto*, void* obj, int level, const char* text) {
        if (level & (MOSQ_LOG_ERR | MOSQ_LOG_WARNING))
            static_cast<Impl*>(obj)->library_error = text;
        log().debug("libmosquitto: {}", text);
    });
    int rc = MOSQ_ERR_SUCCESS;
    if (!config.username.empty())
        rc = mosquitto_username_pw_set(mosq, config.username.c_str(),
                                       config.password_file.empty() ? nullptr : password.c_str());
    if (rc != MOSQ_ERR_SUCCESS) return std::string("username: ") + mosquitto_strerror(rc);
    const std::string will = topic("state");
    rc = mosquitto_will_set(mosq, will.c_str(), static_cast<int>(will_payload.size()),
                            will_payload.data(), 1, true);
    if (rc != MOSQ_ERR_SUCCESS) return std::string("last will: ") + mosquitto_strerror(rc);
    if (!config.tls.ca_file.empty()) {
        // Hostname verification stays on (mosquitto_tls_insecure_set is never called).
        rc = mosquitto_tls_set(mosq, config.tls.ca_file.c_str(), nullptr,
                               c_str_or_null(config.tls.cert_file),
                               c_str_or_null(config.tls.key_file), nullptr);
        if (rc != MOSQ_ERR_SUCCESS)
            return "TLS files (" + config.tls.ca_file.string() + "): " + mosquitto_strerror(rc);
    }
    return "";
}

void Publisher::Impl::attempt() {
    refusal.clear();
    library_error.clear();
    tcp_established = false;
    tcp_closed_at.reset();
    mosq = mosquitto_new(client_id.c_str(), true, this);
    if (!mosq) return fail(std::string("cannot make a client: ") + std::strerror(errno));
    if (const std::string wrong = configure(); !wrong.empty()) return fail(wrong);
    // Non-blocking: the TCP connection, the TLS handshake and CONNACK go on in drive().
    const int rc =
        mosquitto_connect_async(mosq, config.host.c_str(), config.port, config.keepalive_s);
    const int err = errno;
    if (rc != MOSQ_ERR_SUCCESS) fail(reason(rc, err));
}

// One turn of the client: at most 100 ms in select(), then what is due to be sent. A handshake
// that never completes ends in the library's keepalive check (MOSQ_ERR_KEEPALIVE).
void Publisher::Impl::drive() {
    const int rc = mosquitto_loop(mosq, 100, 1);
    const int err = errno;
    if (rc != MOSQ_ERR_SUCCESS) return fail(reason(rc, err));
    if (mosquitto_socket(mosq) < 0) return fail(refusal.empty() ? "connection closed" : refusal);
    if (!connected) {
        if (const std::string why = handshake_problem(); !why.empty()) fail(why);
        return;
    }
    publish_latest();
    publish_next_result();
}

// libmosquitto 2.0.11 does not notice a TCP connection that failed under TLS: the failed
// SSL_connect() is SSL_ERROR_SYSCALL, which it takes for "try again", so it spins until the
// keepalive check ends it with MOSQ_ERR_KEEPALIVE. The socket's TCP state tells at once. Once
// the connection was up, the library gets a second to read why (a TLS alert such as
// "certificate required") before the close is reported without it.
std::string Publisher::Impl::handshake_problem() {
    const int tcp = tcp_state(mosquitto_socket(mosq));
    if (tcp == TCP_ESTABLISHED) tcp_established = true;
    if (tcp != TCP_CLOSE) return "";
    if (!tcp_established) return "connection refused or unreachable";
    const auto now = Clock::now();
    if (!tcp_closed_at) tcp_closed_at = now;
    if (now - *tcp_closed_at < std::chrono::seconds(1)) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));  // the library may spin
        return "";
    }
    return "connection closed by the broker during the handshake" +
           (library_error.empty() ? "" : " (" + library_error + ")");
}

// Why the client stopped, in words: the broker's refusal, the TLS library's complaint
// ("certificate verify failed"), the system's error ("Connection refused") or libmosquitto's.
std::string Publisher::Impl::reason(int rc, int err) const {
    if (!refusal.empty()) return refusal;
    std::string words = rc == MOSQ_ERR_ERRNO ? std::strerror(err) : mosquitto_strerror(rc);
    if (rc == MOSQ_ERR_TLS) words = "TLS handshake failed";
    if (rc == MOSQ_ERR_EAI) words = "cannot resolve the host name";
    if (rc == MOSQ_ERR_KEEPALIVE)  // "Unknown error." in mosquitto_strerror() of 2.0.11
        words = "no answer within the keepalive of " + std::to_string(config.keepalive_s) + " s";
    if (rc == MOSQ_ERR_CONN_LOST) words = "closed by the broker";
    // TLS 1.3 without the client certificate the broker requires: its alert comes after the
    // handshake, and is read now and then as a protocol error (EPROTO) before CONNACK.
    const bool protocol = rc == MOSQ_ERR_PROTOCOL || (rc == MOSQ_ERR_ERRNO && err == EPROTO);
    if (protocol && !connected && !config.tls.ca_file.empty())
        words =
            "the broker ended the connection after the TLS handshake (does it require a "
            "client certificate?)";
    if (!library_error.empty()) words += " (" + library_error + ")";
    return words;
}

void Publisher::Impl::fail(const std::string& why) {
    const bool was_connected = connected;
    connected = false;
    in_flight.reset();  // sent again, first, after the next connection (at least once, in order)
    if (mosq) mosquitto_destroy(mosq);
    mosq = nullptr;
    const double retry_s = delay_s;
    delay_s = std::min(delay_s * 2, config.retry_max_s);
    next_try = Clock::now() + seconds(retry_s);
    const std::string problem = was_connected ? "connection lost: " + why : why;
    log().warn("MQTT broker {}: {}; next try in {:g} s", where(), problem, retry_s);
    std::lock_guard lock(mutex);
    status.connected = false;
    status.problem = problem;
    if (!was_connected) ++status.attempts;
    status.retry_in_s = retry_s;
}

// From the connect callback, inside mosquitto_loop(): what was set is sent again, retained,
// because a broker restarted without persistence has forgotten it.
void Publisher::Impl::on_connected() {
    connected = true;
    delay_s = config.retry_min_s;
    std::lock_guard lock(mutex);
    log().info("MQTT broker {}: connected as {}{}", where(), client_id,
               status.attempts ? fmt::format(" after {} failed attempts", status.attempts) : "");
    status.connected = true;
    status.problem.clear();
    status.attempts = 0;
    status.retry_in_s = 0;
    ++status.connects;
    for (Latest* l : {&state, &health}) l->dirty = !l->json.empty();
}

// The newest state and health, retained; a failed publish stays dirty for the next turn.
void Publisher::Impl::publish_latest() {
    for (auto [leaf, latest] : {std::pair{"state", &state}, std::pair{"health", &health}}) {
        std::string json;
        {
            std::lock_guard lock(mutex);
            if (!latest->dirty) continue;
            json = latest->json;
            latest->dirty = false;
        }
        const int rc = mosquitto_publish(mosq, nullptr, topic(leaf).c_str(),
                                         static_cast<int>(json.size()), json.data(), 1, true);
        if (rc != MOSQ_ERR_SUCCESS) {
            std::lock_guard lock(mutex);
            latest->dirty = true;
        }
    }
}

// One result in flight at a time, so that the broker sees them in the spool's order even
// across reconnections.
void Publisher::Impl::publish_next_result() {
    if (in_flight || Clock::now() < results_paused_until) return;
    const auto message = spool->front();
    if (!message) return;
    int mid = 0;
    const int rc = mosquitto_publish(mosq, &mid, topic("result").c_str(),
                                     static_cast<int>(message->size()), message->data(), 1, false);
    if (rc == MOSQ_ERR_SUCCESS) in_flight = mid;  // else: the next turn finds the fault
}

// From the publish callback: the broker's PUBACK for a result, or for a state or health.
void Publisher::Impl::on_acknowledged(int mid) {
    if (in_flight != mid) return;
    in_flight.reset();
    if (auto ok = spool->pop(); !ok) {
        // Sending on would repeat this result in a tight loop; wait as after a failure.
        log().error("{}; results wait {:g} s", ok.error().message, config.retry_max_s);
        results_paused_until = Clock::now() + seconds(config.retry_max_s);
        return;
    }
    std::lock_guard lock(mutex);
    ++status.published;
}

// A clean stop sends no last will, so the state says "offline" the same way; the DISCONNECT
// then goes out within a few turns (bounded: the broker may be gone).
void Publisher::Impl::shutdown() {
    if (!mosq) return;
    if (connected) {
        mosquitto_publish(mosq, nullptr, topic("state").c_str(),
                          static_cast<int>(will_payload.size()), will_payload.data(), 1, true);
        mosquitto_disconnect(mosq);
        for (int turn = 0; turn < 5 && mosquitto_socket(mosq) >= 0; ++turn)
            mosquitto_loop(mosq, 50, 1);
    }
    mosquitto_destroy(mosq);
    mosq = nullptr;
}

bool valid_topic_level(std::string_view level) {
    return !level.empty() && level.find_first_of("/+#") == std::string_view::npos;
}

core::Result<std::unique_ptr<Publisher>> Publisher::start(const MqttConfig& config) {
    if (auto ok = validate(config); !ok) return ok.error();
    if (auto ok = check_files(config); !ok) return ok.error();
    auto impl = std::make_unique<Impl>();
    impl->config = config;
    if (!config.password_file.empty()) {
        auto password = read_password(config.password_file);
        if (!password) return password.error();
        impl->password = std::move(*password);
    }
    auto spool = Spool::open(config.spool);
    if (!spool) return spool.error();
    impl->spool = std::move(*spool);
    impl->client_id =
        config.client_id.empty() ? "hotgauge-" + config.site + "-" + config.cell : config.client_id;
    impl->will_payload =
        nlohmann::json{{"state", "offline"}, {"site", config.site}, {"cell", config.cell}}.dump();
    impl->delay_s = config.retry_min_s;
    init_library();
    impl->thread = std::thread([self = impl.get()] { self->run(); });
    return std::unique_ptr<Publisher>(new Publisher(std::move(impl)));
}

Publisher::Publisher(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Publisher::~Publisher() {
    impl_->stop = true;
    impl_->thread.join();
}

core::Result<void> Publisher::result(std::string_view json_line) {
    return impl_->spool->append(json_line);
}

std::optional<std::string> Publisher::last_result() const { return impl_->spool->last_appended(); }

core::Result<void> Publisher::start_after(std::string_view json_line) {
    return impl_->spool->start_after(json_line);
}

void Publisher::state(std::string json) {
    std::lock_guard lock(impl_->mutex);
    impl_->state = {std::move(json), true};
}

void Publisher::health(std::string json) {
    std::lock_guard lock(impl_->mutex);
    impl_->health = {std::move(json), true};
}

PublisherStatus Publisher::status() const {
    PublisherStatus s;
    {
        std::lock_guard lock(impl_->mutex);
        s = impl_->status;
    }
    s.spool = impl_->spool->state();
    return s;
}

std::string Publisher::topic(std::string_view leaf) const { return impl_->topic(leaf); }

}  // namespace hotgauge::plant
