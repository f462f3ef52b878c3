// The plant's disk spool on a temp folder, and the MQTT publisher against a
// real broker: Debian's mosquitto started per test on a loopback address of its
// own (127.0.0.21 to .24) and a free port, with TLS (a CA and server
// certificate made at test time by the openssl command line) and a password
// file from mosquitto_passwd. The test's subscriber is a libmosquitto client.
#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <mosquitto.h>
#include <netinet/in.h>
#include <poll.h>
#include <pwd.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "hotgauge/plant/mqtt.hpp"
#include "hotgauge/plant/spool.hpp"
#include "temp_dir.hpp"

extern char** environ;

namespace {

using namespace hotgauge;
using namespace std::chrono_literals;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream all;
    all << in.rdbuf();
    return all.str();
}

void write_file(const fs::path& p, const std::string& text) {
    std::ofstream(p, std::ios::binary) << text;
}

// Polls until pred() holds or the time is up (every wait in these tests is
// bounded).
bool eventually(const std::function<bool()>& pred, std::chrono::milliseconds timeout) {
    const auto until = Clock::now() + timeout;
    while (!pred()) {
        if (Clock::now() > until) return false;
        std::this_thread::sleep_for(10ms);
    }
    return true;
}

double seconds_since(Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
}

// ---------------------------------------------------------------------------------------------
// Spool

plant::SpoolConfig spool_config(const fs::path& dir, std::uint64_t max_bytes = 1 << 20) {
    plant::SpoolConfig c;
    c.dir = dir;
    c.max_bytes = max_bytes;
    return c;
}

std::unique_ptr<plant::Spool> open_spool(const plant::SpoolConfig& c) {
    auto s = plant::Spool::open(c);
    EXPECT_TRUE(s.ok()) << (s ? "" : s.error().message);
    return s ? std::move(*s) : nullptr;
}

// Every message still in the spool, oldest first, popping them all.
std::vector<std::string> drain(plant::Spool& s) {
    std::vector<std::string> out;
    for (int guard = 0; guard < 1000; ++guard) {
        const auto m = s.front();
        if (!m) break;
        out.push_back(*m);
        EXPECT_TRUE(s.pop().ok());
    }
    return out;
}

TEST(Spool, AppendFrontPopInOrder) {
    test::TempDir d;
    auto s = open_spool(spool_config(d.path));
    ASSERT_TRUE(s);
    EXPECT_FALSE(s->front());
    for (const char* m : {"{\"a\":1}", "{\"b\":2}", "{\"c\":3}"}) ASSERT_TRUE(s->append(m).ok());
    EXPECT_EQ(s->state().depth, 3u);
    EXPECT_EQ(s->state().bytes, 24u);
    EXPECT_EQ(s->front(), "{\"a\":1}");
    EXPECT_EQ(s->front(), "{\"a\":1}");  // front() does not consume
    EXPECT_EQ(drain(*s), (std::vector<std::string>{"{\"a\":1}", "{\"b\":2}", "{\"c\":3}"}));
    EXPECT_EQ(s->state().depth, 0u);
    EXPECT_FALSE(s->pop().ok());
    EXPECT_EQ(s->dir(), d.path);
}

TEST(Spool, ReopenAfterPopsKeepsTheRest) {
    test::TempDir d;
    {
        auto s = open_spool(spool_config(d.path));
        ASSERT_TRUE(s);
        for (int i = 0; i < 5; ++i) ASSERT_TRUE(s->append("m" + std::to_string(i)).ok());
        ASSERT_TRUE(s->pop().ok());
        ASSERT_TRUE(s->pop().ok());
    }
    auto s = open_spool(spool_config(d.path));
    ASSERT_TRUE(s);
    EXPECT_EQ(s->state().depth, 3u);
    EXPECT_EQ(s->state().bytes, 9u);
    EXPECT_EQ(drain(*s), (std::vector<std::string>{"m2", "m3", "m4"}));
}

TEST(Spool, TornLastLineIsCutAtOpen) {
    test::TempDir d;
    const std::string long_line = "{\"long\":\"" + std::string(9000, 'y') + "\"}";
    {
        auto s = open_spool(spool_config(d.path));
        ASSERT_TRUE(s);
        ASSERT_TRUE(s->append("m0").ok());
        ASSERT_TRUE(s->append(long_line).ok());
    }
    // The power went here, in a line longer than the blocks the spool reads.
    std::ofstream(d.path / "spool.jsonl", std::ios::app) << "{\"torn" << std::string(10000, 'x');
    auto s = open_spool(spool_config(d.path));
    ASSERT_TRUE(s);
    EXPECT_EQ(slurp(d.path / "spool.jsonl"), "m0\n" + long_line + "\n");
    EXPECT_EQ(s->state().depth, 2u);
    ASSERT_TRUE(s->append("m2").ok());
    EXPECT_EQ(drain(*s), (std::vector<std::string>{"m0", long_line, "m2"}));
}

TEST(Spool, CursorPastTheEndReadsAsZero) {
    test::TempDir d;
    write_file(d.path / "spool.jsonl", "a\nb\n");
    write_file(d.path / "spool.cursor", "1000\n");
    {
        auto s = open_spool(spool_config(d.path));
        ASSERT_TRUE(s);
        EXPECT_EQ(s->state().depth, 2u);
        EXPECT_EQ(s->front(), "a");
    }
    // The crash between emptying the file and writing cursor 0: nothing is sent
    // again.
    write_file(d.path / "spool.jsonl", "");
    write_file(d.path / "spool.cursor", "4\n");
    auto s = open_spool(spool_config(d.path));
    ASSERT_TRUE(s);
    EXPECT_EQ(s->state().depth, 0u);
    EXPECT_FALSE(s->front());
    EXPECT_EQ(slurp(d.path / "spool.cursor"), "0\n");
}

TEST(Spool, BoundRefusesAndCounts) {
    test::TempDir d;
    auto s = open_spool(spool_config(d.path, 10));
    ASSERT_TRUE(s);
    ASSERT_TRUE(s->append("12345").ok());    // 6 bytes with its newline
    const auto refused = s->append("1234");  // 6 + 5 > 10
    ASSERT_FALSE(refused.ok());
    EXPECT_NE(refused.error().message.find(d.path.string()), std::string::npos)
        << refused.error().message;
    EXPECT_NE(refused.error().message.find("10 bytes"), std::string::npos)
        << refused.error().message;
    EXPECT_EQ(s->state().refused, 1u);
    EXPECT_TRUE(s->state().full);
    EXPECT_EQ(s->state().depth, 1u);
    EXPECT_EQ(slurp(d.path / "spool.jsonl"),
              "12345\n");  // what is spooled is untouched
    EXPECT_FALSE(s->append("with\nnewline").ok());
    EXPECT_EQ(s->state().refused, 2u);
    ASSERT_TRUE(s->append("123").ok());  // exactly 10
    EXPECT_FALSE(s->state().full);
    EXPECT_EQ(drain(*s), (std::vector<std::string>{"12345", "123"}));
    EXPECT_TRUE(s->append("1234").ok());  // room again once acknowledged
}

TEST(Spool, FullyAcknowledgedEmptiesTheFile) {
    test::TempDir d;
    auto s = open_spool(spool_config(d.path));
    ASSERT_TRUE(s);
    for (const char* m : {"x1", "x2", "x3"}) ASSERT_TRUE(s->append(m).ok());
    ASSERT_TRUE(s->pop().ok());
    ASSERT_TRUE(s->pop().ok());
    EXPECT_EQ(fs::file_size(d.path / "spool.jsonl"),
              9u);  // kept while one is waiting
    EXPECT_EQ(slurp(d.path / "spool.cursor"), "6\n");
    ASSERT_TRUE(s->pop().ok());
    EXPECT_EQ(fs::file_size(d.path / "spool.jsonl"), 0u);
    EXPECT_EQ(slurp(d.path / "spool.cursor"), "0\n");
    ASSERT_TRUE(s->append("y1").ok());
    EXPECT_EQ(s->front(), "y1");
    EXPECT_EQ(slurp(d.path / "spool.jsonl"), "y1\n");
}

// Where a writer goes on after a crash (the daemon's results, docs/plant-data.md): the newest
// message appended, from the file while it has one, and kept aside once it is emptied.
TEST(Spool, TheLastAppendedMessageOutlivesItsAcknowledgement) {
    test::TempDir d;
    {
        auto s = open_spool(spool_config(d.path));
        ASSERT_TRUE(s);
        EXPECT_FALSE(s->last_appended()) << "never appended to";
        const std::string big(10000, 'b');  // longer than one read block
        for (const std::string& m : {std::string("a1"), big}) ASSERT_TRUE(s->append(m).ok());
        EXPECT_EQ(s->last_appended(), big);
        ASSERT_TRUE(s->pop().ok());
        EXPECT_EQ(s->last_appended(), big);
        ASSERT_TRUE(s->pop().ok());  // emptied
        EXPECT_EQ(fs::file_size(d.path / "spool.jsonl"), 0u);
        EXPECT_EQ(s->last_appended(), big);
        ASSERT_TRUE(s->append("c3").ok());
        EXPECT_EQ(s->last_appended(), "c3");
        ASSERT_TRUE(s->pop().ok());
    }
    auto s = open_spool(spool_config(d.path));
    ASSERT_TRUE(s);
    EXPECT_EQ(s->last_appended(), "c3");
    ASSERT_TRUE(s->start_after("z0").ok());
    EXPECT_EQ(s->last_appended(), "c3") << "only a spool never appended to takes a start";
    test::TempDir fresh;
    auto t = open_spool(spool_config(fresh.path));
    ASSERT_TRUE(t);
    ASSERT_TRUE(t->start_after("{\"sequence\":7}").ok());
    EXPECT_EQ(t->last_appended(), "{\"sequence\":7}");
    EXPECT_EQ(t->state().depth, 0u) << "nothing to send";
}

// ---------------------------------------------------------------------------------------------
// A real broker

const char* const kUser = "hotgauge";
const char* const kPassword = "s3cret pass";

bool run(const std::string& command, const fs::path& log) {
    return std::system((command + " >>" + log.string() + " 2>&1").c_str()) == 0;
}

// The test's certificates, made once: a CA, a server certificate it signs for
// 127.0.0.21 to .24, one it signs for another address (hostname check), a
// client certificate, and a second CA that signed none of them; and the
// broker's password file.
struct Pki {
    test::TempDir dir;
    fs::path ca, other_ca, server_crt, server_key, wrong_host_crt, wrong_host_key, client_crt,
        client_key, passwords, log = dir.path / "openssl.log";
    bool ok = false;

    Pki() {
        const fs::path& p = dir.path;
        ca = p / "ca.crt";
        other_ca = p / "other-ca.crt";
        server_crt = p / "server.crt";
        server_key = p / "server.key";
        wrong_host_crt = p / "wrong-host.crt";
        wrong_host_key = p / "wrong-host.key";
        client_crt = p / "client.crt";
        client_key = p / "client.key";
        passwords = p / "passwords";
        ok = make_ca("ca") && make_ca("other-ca") &&
             make_cert("server",
                       "subjectAltName=IP:127.0.0.21,IP:127.0.0.22,IP:127.0.0.23,"
                       "IP:127.0.0.24") &&
             make_cert("wrong-host", "subjectAltName=IP:127.0.0.99") &&
             make_cert("client", "extendedKeyUsage=clientAuth") &&
             run("mosquitto_passwd -c -b " + passwords.string() + " " + kUser + " '" + kPassword +
                     "'",
                 log);
    }
    bool make_ca(const std::string& name) {
        const fs::path p = dir.path / name;
        return run(
            "openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 "
            "-nodes -days 2 "
            "-subj '/CN=hotgauge test " +
                name + "' -keyout " + p.string() + ".key -out " + p.string() + ".crt",
            log);
    }
    bool make_cert(const std::string& name, const std::string& extension) {
        const fs::path p = dir.path / name;
        write_file(p.string() + ".ext", extension + "\n");
        static int serial = 1;
        return run("openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes "
                   "-subj "
                   "'/CN=hotgauge test " +
                       name + "' -keyout " + p.string() + ".key -out " + p.string() + ".csr",
                   log) &&
               run("openssl x509 -req -days 2 -in " + p.string() + ".csr -CA " + ca.string() +
                       " -CAkey " + (dir.path / "ca.key").string() + " -set_serial " +
                       std::to_string(++serial) + " -extfile " + p.string() + ".ext -out " +
                       p.string() + ".crt",
                   log);
    }
};

const Pki& pki() {
    static const Pki made;
    return made;
}

// A port nobody listens on at this address right now.
int free_port(const std::string& address) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    ::inet_pton(AF_INET, address.c_str(), &a.sin_addr);
    socklen_t len = sizeof a;
    int port = 0;
    if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
        ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0)
        port = ntohs(a.sin_port);
    ::close(fd);
    return port;
}

bool accepts(const std::string& address, int port) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    ::inet_pton(AF_INET, address.c_str(), &a.sin_addr);
    const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
    ::close(fd);
    return ok;
}

struct BrokerOptions {
    bool require_certificate = false;
    bool persistence = false;  // the subscriber's session kept over a restart
    bool wrong_host_certificate = false;
};

// /usr/sbin/mosquitto as a child process, killed and reaped by the destructor.
class Broker {
  public:
    Broker(const fs::path& dir, std::string address, BrokerOptions o = {})
        : address_(std::move(address)), port_(free_port(address_)), dir_(dir) {
        const Pki& p = pki();
        const passwd* me = ::getpwuid(::getuid());
        std::ostringstream conf;
        conf << "per_listener_settings false\nallow_anonymous false\n"
             << "password_file " << p.passwords.string() << "\n"
             << "user " << (me ? me->pw_name : "root") << "\n"  // as root: stay, read our files
             << "log_dest stderr\nlog_type all\n"
             << "persistence " << (o.persistence ? "true" : "false") << "\n"
             << "persistence_location " << dir.string() << "/\n"
             << "listener " << port_ << " " << address_ << "\n"
             << "cafile " << p.ca.string() << "\n"
             << "certfile " << (o.wrong_host_certificate ? p.wrong_host_crt : p.server_crt).string()
             << "\nkeyfile "
             << (o.wrong_host_certificate ? p.wrong_host_key : p.server_key).string()
             << "\nrequire_certificate " << (o.require_certificate ? "true" : "false") << "\n";
        write_file(dir / "mosquitto.conf", conf.str());
    }
    ~Broker() { stop(SIGKILL); }
    Broker(const Broker&) = delete;
    Broker& operator=(const Broker&) = delete;

    // Started and accepting TCP connections within 5 s.
    bool start() {
        posix_spawn_file_actions_t actions;
        posix_spawn_file_actions_init(&actions);
        const std::string log = (dir_ / "mosquitto.log").string();
        posix_spawn_file_actions_addopen(&actions, 2, log.c_str(), O_WRONLY | O_CREAT | O_APPEND,
                                         0644);
        posix_spawn_file_actions_adddup2(&actions, 2, 1);
        const std::string conf = (dir_ / "mosquitto.conf").string();
        char* argv[] = {const_cast<char*>("/usr/sbin/mosquitto"), const_cast<char*>("-c"),
                        const_cast<char*>(conf.c_str()), nullptr};
        const int rc = ::posix_spawn(&pid_, argv[0], &actions, nullptr, argv, environ);
        posix_spawn_file_actions_destroy(&actions);
        if (rc != 0) return false;
        return eventually(
                   [&] {
                       if (::waitpid(pid_, nullptr, WNOHANG) == pid_) pid_ = -1;  // it exited
                       return pid_ < 0 || accepts(address_, port_);
                   },
                   5s) &&
               pid_ > 0;
    }
    // Signalled and reaped; SIGKILL after 5 s.
    void stop(int signal = SIGTERM) {
        if (pid_ <= 0) return;
        ::kill(pid_, signal);
        if (!eventually([&] { return ::waitpid(pid_, nullptr, WNOHANG) == pid_; }, 5s)) {
            ::kill(pid_, SIGKILL);
            ::waitpid(pid_, nullptr, 0);
        }
        pid_ = -1;
    }
    std::string log() const { return slurp(dir_ / "mosquitto.log"); }
    const std::string& address() const { return address_; }
    int port() const { return port_; }

  private:
    std::string address_;
    int port_;
    fs::path dir_;
    pid_t pid_ = -1;
};

struct Message {
    std::string topic, payload;
    bool retained = false;
};

// A libmosquitto client subscribed to hotgauge/# at QoS 1, in its own thread
// (mosquitto_loop_start), reconnecting every second when the broker goes away.
class Subscriber {
  public:
    Subscriber(const Broker& b, const char* id = nullptr) {
        static std::once_flag once;  // never cleaned up: the publisher shares the library
        std::call_once(once, [] { mosquitto_lib_init(); });
        mosq_ = mosquitto_new(id, id == nullptr, this);  // with an id: a session kept
        mosquitto_username_pw_set(mosq_, kUser, kPassword);
        mosquitto_tls_set(mosq_, pki().ca.c_str(), nullptr, nullptr, nullptr, nullptr);
        mosquitto_reconnect_delay_set(mosq_, 1, 1, false);
        mosquitto_connect_callback_set(mosq_, [](mosquitto* m, void*, int rc) {
            if (rc == 0) mosquitto_subscribe(m, nullptr, "hotgauge/#", 1);
        });
        mosquitto_subscribe_callback_set(mosq_, [](mosquitto*, void* self, int, int, const int*) {
            static_cast<Subscriber*>(self)->subscribed_ = true;
        });
        mosquitto_message_callback_set(
            mosq_, [](mosquitto*, void* self, const mosquitto_message* m) {
                auto& s = *static_cast<Subscriber*>(self);
                std::lock_guard lock(s.mutex_);
                s.messages_.push_back({m->topic,
                                       std::string(static_cast<const char*>(m->payload),
                                                   static_cast<std::size_t>(m->payloadlen)),
                                       m->retain});
            });
        connected_ =
            mosquitto_connect_async(mosq_, b.address().c_str(), b.port(), 5) == MOSQ_ERR_SUCCESS &&
            mosquitto_loop_start(mosq_) == MOSQ_ERR_SUCCESS;
    }
    ~Subscriber() {
        mosquitto_disconnect(mosq_);
        if (connected_) mosquitto_loop_stop(mosq_, false);
        mosquitto_destroy(mosq_);
    }
    Subscriber(const Subscriber&) = delete;
    Subscriber& operator=(const Subscriber&) = delete;

    bool wait_subscribed() {
        return connected_ && eventually([&] { return subscribed_.load(); }, 5s);
    }
    std::vector<Message> messages(const std::string& topic) const {
        std::lock_guard lock(mutex_);
        std::vector<Message> out;
        for (const auto& m : messages_)
            if (m.topic == topic) out.push_back(m);
        return out;
    }
    std::vector<std::string> payloads(const std::string& topic) const {
        std::vector<std::string> out;
        for (const auto& m : messages(topic)) out.push_back(m.payload);
        return out;
    }

  private:
    mosquitto* mosq_ = nullptr;
    bool connected_ = false;
    std::atomic<bool> subscribed_{false};
    mutable std::mutex mutex_;
    std::vector<Message> messages_;
};

plant::MqttConfig publisher_config(const fs::path& dir, const Broker& b) {
    plant::MqttConfig c;
    c.enabled = true;
    c.host = b.address();
    c.port = b.port();
    c.site = "plant1";
    c.cell = "cell7";
    c.username = kUser;
    c.password_file = dir / "mqtt-password";
    write_file(c.password_file, std::string(kPassword) + "\n");
    c.tls.ca_file = pki().ca;
    c.keepalive_s = 5;
    c.retry_min_s = 0.2;
    c.retry_max_s = 1.0;
    c.spool.dir = dir / "spool";
    return c;
}

std::unique_ptr<plant::Publisher> start_publisher(const plant::MqttConfig& c) {
    auto p = plant::Publisher::start(c);
    EXPECT_TRUE(p.ok()) << (p ? "" : p.error().message);
    return p ? std::move(*p) : nullptr;
}

// A result line with what JSON escapes and what UTF-8 adds, so that byte
// identity means something.
std::string result_line(int sequence) {
    return nlohmann::json{{"sequence", sequence},
                          {"part", {{"part_id", "4711-Ä"}, {"note", "a \"quoted\" \\ tab\t"}}}}
        .dump();
}

// The destructor's time, in seconds: it must never wait for the broker.
double stop_time_s(std::unique_ptr<plant::Publisher>& p) {
    const auto t0 = Clock::now();
    p.reset();
    return seconds_since(t0);
}

class Mqtt : public ::testing::Test {
  protected:
    void SetUp() override { ASSERT_TRUE(pki().ok) << slurp(pki().log); }
    test::TempDir dir;
};

TEST_F(Mqtt, DeliversInOrderExactlyOnceOverTlsWithPassword) {
    Broker broker(dir.path, "127.0.0.21");
    ASSERT_TRUE(broker.start()) << broker.log();
    Subscriber sub(broker);
    ASSERT_TRUE(sub.wait_subscribed()) << broker.log();
    const auto config = publisher_config(dir.path, broker);
    std::vector<std::string> sent;
    {  // results spooled by a previous run, before the broker was configured
        auto spool = open_spool(config.spool);
        ASSERT_TRUE(spool);
        for (int i = 0; i < 5; ++i)
            ASSERT_TRUE(spool->append(sent.emplace_back(result_line(i))).ok());
    }
    auto p = start_publisher(config);
    ASSERT_TRUE(p);
    EXPECT_EQ(p->topic("result"), "hotgauge/plant1/cell7/result");
    p->state(R"({"state":"running"})");
    p->health(R"({"camera":"ok"})");
    for (int i = 5; i < 30; ++i) ASSERT_TRUE(p->result(sent.emplace_back(result_line(i))).ok());

    ASSERT_TRUE(eventually([&] { return p->status().spool.depth == 0; }, 10s))
        << p->status().problem << "\n"
        << broker.log();
    ASSERT_TRUE(eventually([&] { return sub.payloads(p->topic("result")).size() >= 30; }, 5s));
    std::this_thread::sleep_for(200ms);  // time for a duplicate to show, if one was sent
    EXPECT_EQ(sub.payloads(p->topic("result")), sent);
    for (const auto& m : sub.messages(p->topic("result"))) EXPECT_FALSE(m.retained);
    const auto status = p->status();
    EXPECT_TRUE(status.connected);
    EXPECT_EQ(status.problem, "");
    EXPECT_EQ(status.published, 30u);
    EXPECT_EQ(status.connects, 1u);
    EXPECT_EQ(status.attempts, 0u);

    // State and health are retained: a subscriber that comes later gets them.
    Subscriber late(broker);
    ASSERT_TRUE(late.wait_subscribed());
    ASSERT_TRUE(eventually(
        [&] {
            return !late.messages(p->topic("state")).empty() &&
                   !late.messages(p->topic("health")).empty();
        },
        5s));
    EXPECT_EQ(late.messages(p->topic("state")).back().payload, R"({"state":"running"})");
    EXPECT_TRUE(late.messages(p->topic("state")).back().retained);
    EXPECT_EQ(late.messages(p->topic("health")).back().payload, R"({"camera":"ok"})");
    EXPECT_TRUE(late.messages(p->topic("health")).back().retained);
    EXPECT_TRUE(late.messages(p->topic("result")).empty());  // results are not retained

    // A clean stop says "offline" in the state, as the last will would.
    const std::string state_topic = p->topic("state");
    EXPECT_LT(stop_time_s(p), 2.0);
    ASSERT_TRUE(eventually([&] { return late.messages(state_topic).size() >= 2; }, 5s));
    const auto offline = nlohmann::json::parse(late.messages(state_topic).back().payload);
    EXPECT_EQ(offline,
              (nlohmann::json{{"state", "offline"}, {"site", "plant1"}, {"cell", "cell7"}}));
}

TEST_F(Mqtt, BrokerRestartLosesNothingAndRepeatsNothing) {
    Broker broker(dir.path, "127.0.0.22", {.persistence = true});
    ASSERT_TRUE(broker.start()) << broker.log();
    Subscriber sub(broker, "test-subscriber");  // its session and queue survive the restart
    ASSERT_TRUE(sub.wait_subscribed()) << broker.log();
    auto p = start_publisher(publisher_config(dir.path, broker));
    ASSERT_TRUE(p);
    const std::string topic = p->topic("result");
    std::vector<std::string> sent;
    for (int i = 0; i < 5; ++i) ASSERT_TRUE(p->result(sent.emplace_back(result_line(i))).ok());
    ASSERT_TRUE(eventually([&] { return sub.payloads(topic).size() >= 5; }, 10s))
        << p->status().problem;

    broker.stop(SIGTERM);
    ASSERT_TRUE(eventually([&] { return !p->status().connected; }, 5s));
    double slowest_s = 0;
    for (int i = 5; i < 15; ++i) {
        const auto t0 = Clock::now();
        ASSERT_TRUE(p->result(sent.emplace_back(result_line(i))).ok());
        slowest_s = std::max(slowest_s, seconds_since(t0));
        EXPECT_EQ(p->status().spool.depth, static_cast<std::uint64_t>(i - 4));
    }
    EXPECT_LT(slowest_s, 0.1) << "result() waited for the broker";
    std::cout << "slowest result() while the broker was down: " << slowest_s * 1e3 << " ms\n";
    EXPECT_NE(p->status().problem, "");

    ASSERT_TRUE(broker.start()) << broker.log();
    ASSERT_TRUE(eventually([&] { return sub.payloads(topic).size() >= 15; }, 10s))
        << p->status().problem << "\n"
        << broker.log();
    EXPECT_TRUE(eventually([&] { return p->status().spool.depth == 0; }, 2s));
    std::this_thread::sleep_for(200ms);  // time for a duplicate to show, if one was sent
    EXPECT_EQ(sub.payloads(topic), sent);
    EXPECT_EQ(p->status().published, 15u);
    EXPECT_EQ(p->status().connects, 2u);
}

TEST_F(Mqtt, WrongPasswordIsRetriedWithAGrowingDelay) {
    Broker broker(dir.path, "127.0.0.23");
    ASSERT_TRUE(broker.start()) << broker.log();
    auto config = publisher_config(dir.path, broker);
    write_file(config.password_file, "not the password\n");
    auto p = start_publisher(config);
    ASSERT_TRUE(p);
    ASSERT_TRUE(p->result(result_line(1)).ok());
    ASSERT_TRUE(p->result(result_line(2)).ok());
    ASSERT_TRUE(eventually([&] { return p->status().attempts >= 1; }, 5s));
    const double first_delay_s = p->status().retry_in_s;
    ASSERT_TRUE(eventually([&] { return p->status().attempts >= 3; }, 8s));
    const auto status = p->status();
    EXPECT_GT(status.retry_in_s, first_delay_s);
    EXPECT_FALSE(status.connected);
    EXPECT_TRUE(status.problem.find("not authorised") != std::string::npos ||
                status.problem.find("bad username or password") != std::string::npos)
        << status.problem;
    EXPECT_EQ(status.published, 0u);
    EXPECT_EQ(status.connects, 0u);
    EXPECT_EQ(status.spool.depth, 2u);  // nothing popped
    EXPECT_LT(stop_time_s(p), 2.0);
}

// Waits for the first failed attempt and returns the problem; the publisher is
// then stopped, which must take less than 2 s.
std::string first_problem(const plant::MqttConfig& config) {
    auto p = start_publisher(config);
    if (!p) return "";
    EXPECT_TRUE(eventually([&] { return p->status().attempts >= 1; }, 5s));
    const auto status = p->status();
    EXPECT_FALSE(status.connected);
    EXPECT_LT(stop_time_s(p), 2.0);
    return status.problem;
}

TEST_F(Mqtt, WrongCaFailsTheHandshakeNamingTheCertificate) {
    Broker broker(dir.path, "127.0.0.23");
    ASSERT_TRUE(broker.start()) << broker.log();
    auto config = publisher_config(dir.path, broker);
    config.tls.ca_file = pki().other_ca;
    const std::string problem = first_problem(config);
    EXPECT_NE(problem.find("certificate"), std::string::npos) << problem;
    std::cout << "wrong CA: " << problem << "\n";
}

TEST_F(Mqtt, ServerCertificateForAnotherAddressIsRefused) {
    Broker broker(dir.path, "127.0.0.23", {.wrong_host_certificate = true});
    ASSERT_TRUE(broker.start()) << broker.log();
    const std::string problem = first_problem(publisher_config(dir.path, broker));
    EXPECT_NE(problem.find("certificate"), std::string::npos) << problem;
    std::cout << "wrong host: " << problem << "\n";
}

TEST_F(Mqtt, UnreachablePortIsRefused) {
    Broker nobody(dir.path,
                  "127.0.0.24");  // configured, never started: its port is free
    const std::string problem = first_problem(publisher_config(dir.path, nobody));
    EXPECT_NE(problem.find("refused"), std::string::npos) << problem;
    std::cout << "unreachable: " << problem << "\n";
}

// A peer that takes the TCP connection (the kernel's backlog) and never answers
// the TLS hello.
TEST_F(Mqtt, StopsPromptlyInTheMiddleOfAHandshake) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    ::inet_pton(AF_INET, "127.0.0.24", &a.sin_addr);
    socklen_t len = sizeof a;
    ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    ASSERT_EQ(::listen(fd, 4), 0);
    ASSERT_EQ(::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len), 0);
    Broker silent(dir.path, "127.0.0.24");  // for its configuration only
    auto config = publisher_config(dir.path, silent);
    config.port = ntohs(a.sin_port);
    auto p = start_publisher(config);
    ASSERT_TRUE(p);
    std::this_thread::sleep_for(500ms);
    EXPECT_FALSE(p->status().connected);
    EXPECT_LT(stop_time_s(p), 2.0);
    ::close(fd);
}

TEST_F(Mqtt, ClientCertificateIsAcceptedWhereRequired) {
    Broker broker(dir.path, "127.0.0.24", {.require_certificate = true});
    ASSERT_TRUE(broker.start()) << broker.log();
    auto config = publisher_config(dir.path, broker);
    {  // without one: no connection
        config.spool.dir = dir.path / "spool-without";
        auto p = start_publisher(config);
        ASSERT_TRUE(p);
        EXPECT_TRUE(eventually([&] { return p->status().attempts >= 1; }, 5s));
        EXPECT_EQ(p->status().connects, 0u);
        // The broker's TLS alert ("certificate required"), or only its closing the
        // connection.
        EXPECT_TRUE(p->status().problem.find("certificate") != std::string::npos ||
                    p->status().problem.find("closed by the broker") != std::string::npos)
            << p->status().problem;
        std::cout << "no client certificate: " << p->status().problem << "\n";
    }
    config.spool.dir = dir.path / "spool";
    config.tls.cert_file = pki().client_crt;
    config.tls.key_file = pki().client_key;
    auto p = start_publisher(config);
    ASSERT_TRUE(p);
    ASSERT_TRUE(p->result(result_line(1)).ok());
    EXPECT_TRUE(eventually([&] { return p->status().published == 1; }, 5s))
        << p->status().problem << "\n"
        << broker.log();
    EXPECT_EQ(p->status().connects, 1u);
}

// The last will: a publisher whose process dies (SIGKILL) without DISCONNECT,
// in a child process forked while this process has no other thread.
TEST_F(Mqtt, LastWillSaysOfflineWhenTheConnectionDies) {
    Broker broker(dir.path, "127.0.0.21");
    ASSERT_TRUE(broker.start()) << broker.log();
    const auto config = publisher_config(dir.path, broker);
    int ready[2];
    ASSERT_EQ(::pipe(ready), 0);
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
        ::close(ready[0]);
        auto p = plant::Publisher::start(config);
        if (!p) ::_exit(2);
        (*p)->state(R"({"state":"running"})");
        for (int i = 0; i < 500 && !(*p)->status().connected; ++i) ::usleep(10'000);
        if (::write(ready[1], "c", 1) != 1) ::_exit(3);
        for (;;) ::pause();  // until SIGKILL
    }
    ::close(ready[1]);
    pollfd wait{ready[0], POLLIN, 0};
    char byte = 0;
    const bool signalled = ::poll(&wait, 1, 5000) == 1 && ::read(ready[0], &byte, 1) == 1;
    ::close(ready[0]);
    Subscriber sub(broker);
    const std::string topic = "hotgauge/plant1/cell7/state";
    const bool running = signalled && sub.wait_subscribed() &&
                         eventually([&] { return !sub.messages(topic).empty(); }, 5s);
    ::kill(child, SIGKILL);
    ::waitpid(child, nullptr, 0);
    ASSERT_TRUE(running) << broker.log();
    EXPECT_EQ(sub.messages(topic).front().payload, R"({"state":"running"})");
    ASSERT_TRUE(eventually([&] { return sub.messages(topic).size() >= 2; }, 5s)) << broker.log();
    EXPECT_EQ(nlohmann::json::parse(sub.messages(topic).back().payload),
              (nlohmann::json{{"state", "offline"}, {"site", "plant1"}, {"cell", "cell7"}}));
    Subscriber late(broker);  // and retained
    ASSERT_TRUE(late.wait_subscribed());
    ASSERT_TRUE(eventually([&] { return !late.messages(topic).empty(); }, 5s));
    EXPECT_TRUE(late.messages(topic).back().retained);
    EXPECT_EQ(late.messages(topic).back().payload, sub.messages(topic).back().payload);
}

TEST(MqttStart, RefusesWhatCannotBeRetriedNamingTheFile) {
    test::TempDir dir;
    plant::MqttConfig c;
    c.site = "plant1";
    c.cell = "cell7";
    c.username = kUser;
    c.spool.dir = dir.path / "spool";
    c.password_file = dir.path / "missing-password";
    auto p = plant::Publisher::start(c);
    ASSERT_FALSE(p.ok());
    EXPECT_NE(p.error().message.find("missing-password"), std::string::npos) << p.error().message;
    write_file(c.password_file = dir.path / "password", "x\n");
    c.tls.ca_file = dir.path / "missing-ca.crt";
    p = plant::Publisher::start(c);
    ASSERT_FALSE(p.ok());
    EXPECT_NE(p.error().message.find("missing-ca.crt"), std::string::npos) << p.error().message;
    c.tls.ca_file.clear();
    c.site = "plant/1";
    EXPECT_FALSE(plant::Publisher::start(c).ok());
}

}  // namespace
