#pragma once
// The daemon's status page server (docs/operations.md "Status page") and its metrics endpoint
// for plant IT (docs/plant-data.md "Metrics"): read-only HTTP on a configured address (loopback
// unless configured otherwise). GET and HEAD only, every other method 405; no write action of
// any kind.
//   /              the page (render_status_page), /status.json the same for machines
//   /pictures/<sequence>/<face>.png   the last part's range images
//   /<root>/...    files under the configured folders (results, archive), read-only: a path with
//                  "..", or one that leaves its folder through a link, is refused (403)
// Requests are served by a bounded pool of threads with a bounded queue: when it is full the
// listener stops accepting until a thread is free (the kernel's backlog, then refusal).
// Thread safety: the view source is called from the pool's threads, concurrently.
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "hotgauge/core/result.hpp"
#include "hotgauge/web/cell_view.hpp"

namespace hotgauge::web {

struct FileRoot {
    std::string name;  // URL prefix without slashes: "results" serves /results/...
    std::filesystem::path dir;
};

struct ServerConfig {
    std::string bind_address = "127.0.0.1";
    int port = 8080;  // 0: an ephemeral port (tests)
    int threads = 2;
    int queue = 16;              // connections waiting for a thread
    int read_timeout_ms = 2000;  // a client that sends nothing is dropped after this
    std::vector<FileRoot> roots;
};

// "text/csv; charset=utf-8" for "a.csv": the Content-Type of a served file, by its extension.
std::string content_type(const std::filesystem::path& file);

class Server {
  public:
    using ViewSource = std::function<CellView()>;
    using TextSource = std::function<std::string()>;
    // Binds and starts serving; the error names the address when it cannot be bound.
    static core::Result<std::unique_ptr<Server>> start(const ServerConfig& config, ViewSource view);
    // The metrics endpoint (docs/plant-data.md "Metrics"): GET /metrics answers the source's
    // Prometheus text, every other path 404, with the same read-only rules and limits.
    static core::Result<std::unique_ptr<Server>> start_metrics(const ServerConfig& config,
                                                               TextSource metrics);
    ~Server();  // stops and joins: no request is served after it returns
    Server(const Server&) = delete;
    Server& operator=(const Server&) = delete;

    int port() const;
    std::string url() const;  // "http://127.0.0.1:8080/"

  private:
    struct Impl;
    explicit Server(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hotgauge::web
