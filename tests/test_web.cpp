// The status page's server (web::Server) over real HTTP on a loopback ephemeral port, with a
// plain socket client that sends the request line as written (no client-side path cleaning);
// and the daemon's StatusBoard behind it.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "hotgauge/cell/status_board.hpp"
#include "hotgauge/web/server.hpp"
#include "temp_dir.hpp"

namespace {

using namespace hotgauge;
namespace fs = std::filesystem;

struct Reply {
    int status = 0;
    std::string head, body;
    std::string header(const std::string& name) const {  // lower-case name
        std::string lower = head;
        for (auto& ch : lower) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
        const auto at = lower.find("\r\n" + name + ":");
        if (at == std::string::npos) return "";
        const auto from = at + name.size() + 3, to = head.find("\r\n", from);
        return head.substr(from + (head[from] == ' ' ? 1 : 0), to - from - (head[from] == ' '));
    }
};

Reply request(int port, const std::string& method, const std::string& target,
              const std::string& body = "") {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    timeval tv{5, 0};
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    Reply r;
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        ::close(fd);
        return r;
    }
    const std::string req = method + " " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\n" +
                            "Connection: close\r\nContent-Length: " + std::to_string(body.size()) +
                            "\r\n\r\n" + body;
    EXPECT_EQ(::send(fd, req.data(), req.size(), 0), static_cast<ssize_t>(req.size()));
    std::string all;
    char buf[65536];
    for (ssize_t n; (n = ::recv(fd, buf, sizeof buf, 0)) > 0;)
        all.append(buf, static_cast<std::size_t>(n));
    ::close(fd);
    const auto end = all.find("\r\n\r\n");
    if (all.rfind("HTTP/1.1 ", 0) != 0 || end == std::string::npos) return r;
    r.status = std::stoi(all.substr(9, 3));
    r.head = all.substr(0, end);
    r.body = all.substr(end + 4);
    return r;
}

// A GET that must answer 200 with this type and these bytes.
void expect_served(int port, const std::string& target, const std::string& type,
                   const std::string& body) {
    const Reply r = request(port, "GET", target);
    EXPECT_EQ(r.status, 200) << target;
    EXPECT_EQ(r.header("content-type"), type) << target;
    EXPECT_EQ(r.body, body) << target;
}

web::CellView sample_view() {
    web::CellView v;
    v.state = "idle: waiting for a trigger";
    v.plc_state = "IDLE";
    v.results.push_back({7,
                         "2026-12-04T10:00:00.000+01:00",
                         "<b>4711</b>",
                         "hub-a",
                         "NOK",
                         "NOK",
                         {{"Diameter 1", 62.2134, "NOK", "above the tolerance"},
                          {"Height 1", std::nullopt, "NOT_MEASURED", "edge not found"}}});
    v.pictures_sequence = 7;
    v.pictures_part_id = "4711";
    v.pictures.push_back({"top", 2, 1,
                          std::make_shared<const std::vector<std::uint8_t>>(
                              std::vector<std::uint8_t>{0x89, 'P', 'N', 'G', 1, 2, 3})});
    return v;
}

struct Served {
    test::TempDir root, outside;
    std::unique_ptr<web::Server> server;
    Served() {
        std::ofstream(root.path / "2026-12-04.csv") << "time,sequence\n1,7\n";
        fs::create_directories(root.path / "rec-7");
        std::ofstream(outside.path / "secret.txt") << "secret";
        fs::create_symlink(outside.path / "secret.txt", root.path / "link.txt");
        web::ServerConfig c;
        c.port = 0;
        c.roots = {{"results", root.path}};
        auto s = web::Server::start(c, [] { return sample_view(); });
        EXPECT_TRUE(s.ok());
        if (s) server = std::move(*s);
    }
    int port() const { return server->port(); }
};

TEST(WebServer, ServesThePageAndItsJson) {
    Served s;
    ASSERT_TRUE(s.server);
    EXPECT_GT(s.port(), 0);
    EXPECT_EQ(s.server->url(), "http://127.0.0.1:" + std::to_string(s.port()) + "/");
    const Reply page = request(s.port(), "GET", "/");
    ASSERT_EQ(page.status, 200);
    EXPECT_EQ(page.header("content-type"), "text/html; charset=utf-8");
    EXPECT_NE(page.header("content-security-policy").find("default-src 'none'"), std::string::npos);
    EXPECT_NE(page.body.find("data-sequence=\"7\""), std::string::npos);
    EXPECT_NE(page.body.find("&lt;b&gt;4711&lt;/b&gt;"), std::string::npos);  // escaped
    EXPECT_EQ(page.body.find("<b>4711"), std::string::npos);
    EXPECT_NE(page.body.find("Diameter 1 62.213 NOK: above the tolerance"), std::string::npos);
    EXPECT_NE(page.body.find("src=\"/pictures/7/top.png\""), std::string::npos);
    EXPECT_NE(page.body.find("not reported yet"), std::string::npos);  // no health yet
    EXPECT_EQ(page.body.find("<script"), std::string::npos);

    const Reply json = request(s.port(), "GET", "/status.json");
    ASSERT_EQ(json.status, 200);
    EXPECT_EQ(json.header("content-type"), "application/json");
    const auto j = nlohmann::json::parse(json.body);
    EXPECT_EQ(j["results"][0]["sequence"], 7);
    EXPECT_EQ(j["results"][0]["part_id"], "<b>4711</b>");
    EXPECT_EQ(j["results"][0]["features"][0]["verdict"], "NOK");
    EXPECT_TRUE(j["results"][0]["features"][1]["value_mm"].is_null());
    EXPECT_TRUE(j["health_updated"].is_null());

    const Reply head = request(s.port(), "HEAD", "/");
    EXPECT_EQ(head.status, 200);
    EXPECT_TRUE(head.body.empty());
}

TEST(WebServer, RefusesEveryMethodButGetAndHead) {
    Served s;
    ASSERT_TRUE(s.server);
    for (const char* m : {"POST", "PUT", "DELETE", "PATCH", "OPTIONS"}) {
        const Reply r = request(s.port(), m, "/", "state=stop");
        EXPECT_EQ(r.status, 405) << m;
        EXPECT_EQ(r.header("allow"), "GET, HEAD") << m;
    }
    EXPECT_EQ(request(s.port(), "POST", "/results/2026-12-04.csv", "x").status, 405);
    // Nothing was written.
    EXPECT_EQ(request(s.port(), "GET", "/results/2026-12-04.csv").body, "time,sequence\n1,7\n");
}

TEST(WebServer, ServesFilesUnderItsRootOnly) {
    Served s;
    ASSERT_TRUE(s.server);
    expect_served(s.port(), "/results/2026-12-04.csv", "text/csv; charset=utf-8",
                  "time,sequence\n1,7\n");
    const Reply list = request(s.port(), "GET", "/results/");
    ASSERT_EQ(list.status, 200);
    EXPECT_NE(list.body.find("href=\"2026-12-04.csv\""), std::string::npos);
    EXPECT_NE(list.body.find("href=\"rec-7/\""), std::string::npos);
    EXPECT_EQ(request(s.port(), "GET", "/results/rec-7").status, 302);  // to rec-7/
    EXPECT_EQ(request(s.port(), "GET", "/results/missing.csv").status, 404);
    for (const char* bad :
         {"/results/../../etc/passwd", "/results/%2e%2e/%2e%2e/etc/passwd",
          "/results/rec-7/../../secret.txt", "/results/./2026-12-04.csv", "/results/link.txt"}) {
        const Reply r = request(s.port(), "GET", bad);
        EXPECT_EQ(r.status, 403) << bad;
        EXPECT_EQ(r.body.find("secret"), std::string::npos) << bad;
        EXPECT_EQ(r.body.find("root:"), std::string::npos) << bad;
    }
    EXPECT_EQ(request(s.port(), "GET", "/files/../../etc/passwd").status, 404);
}

TEST(WebServer, ServesTheLastPartsPicturesByItsSequence) {
    Served s;
    ASSERT_TRUE(s.server);
    expect_served(s.port(), "/pictures/7/top.png", "image/png",
                  std::string("\x89PNG\x01\x02\x03", 7));
    EXPECT_EQ(request(s.port(), "GET", "/pictures/6/top.png").status, 404);  // another part
    EXPECT_EQ(request(s.port(), "GET", "/pictures/7/side1.png").status, 404);
}

TEST(WebServer, ContentTypes) {
    EXPECT_EQ(web::content_type("a/2026-12-04.report.html"), "text/html; charset=utf-8");
    EXPECT_EQ(web::content_type("x.jsonl"), "text/plain; charset=utf-8");
    EXPECT_EQ(web::content_type("x.json"), "application/json");
    EXPECT_EQ(web::content_type("top/x.npy"), "application/octet-stream");
}

TEST(WebServer, ABoundAddressIsAnError) {
    Served s;
    ASSERT_TRUE(s.server);
    web::ServerConfig c;
    c.port = s.port();
    auto again = web::Server::start(c, [] { return web::CellView{}; });
    ASSERT_FALSE(again.ok());
    EXPECT_NE(again.error().message.find("127.0.0.1:" + std::to_string(s.port())),
              std::string::npos);
}

TEST(StatusBoard, ShowsHealthOnlyOnceReported) {
    test::TempDir dir;
    cell::StatusBoard board(dir.path / "results", dir.path / "archive");
    board.set_state("idle");
    web::CellView v = board.view();
    EXPECT_EQ(v.state, "idle");
    EXPECT_TRUE(v.health_updated.empty());
    EXPECT_TRUE(v.devices.empty());
    cell::DeviceHealth h;
    h.updated_ns = 1'700'000'000'000'000'000;
    h[cell::Device::kCamera] = {true, false, "no frames for 3 s"};
    board.set_health(h);
    v = board.view();
    EXPECT_FALSE(v.health_updated.empty());
    ASSERT_EQ(v.devices.size(), static_cast<std::size_t>(cell::kDeviceCount));
    EXPECT_EQ(v.devices[0].name, "camera");
    EXPECT_FALSE(v.devices[0].ok);
    EXPECT_EQ(v.devices[0].detail, "no frames for 3 s");
    board.event("PLC fault 202", true);
    EXPECT_EQ(board.view().events.at(0).text, "PLC fault 202");
    const auto roots = board.roots();
    ASSERT_EQ(roots.size(), 2u);
    EXPECT_EQ(roots[0].name, "results");
}

}  // namespace
