#include "hotgauge/web/server.hpp"

#include <httplib.h>

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <fstream>
#include <map>
#include <mutex>
#include <thread>

#include "hotgauge/core/text.hpp"

namespace hotgauge::web {
namespace {

namespace fs = std::filesystem;

// httplib's own ThreadPool queues without bound (0.11.4); this one makes the listener wait for
// room instead, so that a flood of connections costs the daemon neither threads nor memory.
class BoundedPool : public httplib::TaskQueue {
  public:
    BoundedPool(int threads, int queue) : max_queued_(static_cast<std::size_t>(queue)) {
        for (int i = 0; i < threads; ++i) threads_.emplace_back([this] { work(); });
    }
    void enqueue(std::function<void()> fn) override {
        std::unique_lock lock(mutex_);
        room_.wait(lock, [&] { return jobs_.size() < max_queued_ || stopping_; });
        jobs_.push_back(std::move(fn));
        work_.notify_one();
    }
    void shutdown() override {
        {
            std::lock_guard lock(mutex_);
            stopping_ = true;
        }
        work_.notify_all();
        room_.notify_all();
        for (auto& t : threads_) t.join();
    }

  private:
    void work() {
        for (;;) {
            std::function<void()> fn;
            {
                std::unique_lock lock(mutex_);
                work_.wait(lock, [&] { return !jobs_.empty() || stopping_; });
                if (jobs_.empty()) return;  // stopping, and nothing left
                fn = std::move(jobs_.front());
                jobs_.pop_front();
            }
            room_.notify_one();
            fn();
        }
    }
    std::size_t max_queued_;
    std::mutex mutex_;
    std::condition_variable work_, room_;
    std::deque<std::function<void()>> jobs_;
    bool stopping_ = false;
    std::vector<std::thread> threads_;
};

// Nothing the page does needs more: its own pictures, inline style, no script, no frame.
constexpr const char* kPolicy =
    "default-src 'none'; img-src 'self' data:; style-src 'unsafe-inline'; frame-ancestors 'none'";

// `rel` (the decoded URL path below a root) as a file under `root`: 403 for a path that names
// "." or ".." or leaves the root through a link, 404 for one that is not there.
int resolve(const fs::path& root, const std::string& rel, fs::path& out) {
    std::size_t start = 0;
    while (start <= rel.size()) {
        const std::size_t end = std::min(rel.find('/', start), rel.size());
        const std::string_view seg(rel.data() + start, end - start);
        if (seg == "." || seg == ".." || seg.find('\\') != seg.npos || seg.find('\0') != seg.npos)
            return 403;
        start = end + 1;
    }
    std::error_code ec;
    const fs::path base = fs::canonical(root, ec);
    if (ec) return 404;
    const fs::path p = fs::weakly_canonical(base / rel, ec);
    if (ec) return 404;
    const auto [b, q] = std::mismatch(base.begin(), base.end(), p.begin(), p.end());
    if (b != base.end()) return 403;
    if (!fs::exists(p, ec)) return 404;
    out = p;
    return 200;
}

std::string listing(const std::string& url, const fs::path& dir) {
    std::vector<std::string> names;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir, ec))
        names.push_back(e.path().filename().string() + (e.is_directory(ec) ? "/" : ""));
    std::sort(names.begin(), names.end());
    std::string h = "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>" +
                    core::html_escape(url) + "</title></head><body><h1>" + core::html_escape(url) +
                    "</h1><ul>";
    for (const auto& n : names)
        h += "<li><a href=\"" + core::html_escape(n) + "\">" + core::html_escape(n) + "</a></li>";
    return h + "</ul></body></html>\n";
}

void serve_file(const fs::path& file, httplib::Response& res) {
    std::error_code ec;
    const auto size = fs::file_size(file, ec);
    auto in = std::make_shared<std::ifstream>(file, std::ios::binary);
    if (ec || !*in) {
        res.status = 403;
        return;
    }
    res.set_content_provider(static_cast<std::size_t>(size), content_type(file),
                             [in](std::size_t offset, std::size_t length, httplib::DataSink& sink) {
                                 std::vector<char> buf(std::min<std::size_t>(length, 64 * 1024));
                                 in->seekg(static_cast<std::streamoff>(offset));
                                 in->read(buf.data(), static_cast<std::streamsize>(buf.size()));
                                 const auto got = static_cast<std::size_t>(in->gcount());
                                 return got > 0 && sink.write(buf.data(), got);
                             });
}

void serve_root(const FileRoot& root, const httplib::Request& req, httplib::Response& res) {
    const std::string rel = req.matches[1];
    fs::path p;
    res.status = resolve(root.dir, rel, p);
    if (res.status != 200) return;
    std::error_code ec;
    if (!fs::is_directory(p, ec)) return serve_file(p, res);
    if (!req.path.ends_with("/")) {  // so that the listing's relative links resolve
        res.set_redirect(req.path + "/");
        return;
    }
    res.set_content(listing(req.path, p), "text/html; charset=utf-8");
}

void serve_picture(const CellView& v, const httplib::Request& req, httplib::Response& res) {
    const std::string seq = req.matches[1], face = req.matches[2];
    res.status = 404;
    if (!v.pictures_sequence || std::to_string(*v.pictures_sequence) != seq) return;
    for (const auto& p : v.pictures)
        if (p.face == face && p.png) {
            res.status = 200;
            res.set_header("Cache-Control", "max-age=60");
            res.set_content(reinterpret_cast<const char*>(p.png->data()), p.png->size(),
                            "image/png");
        }
}

}  // namespace

std::string content_type(const fs::path& file) {
    static const std::map<std::string, std::string> types{{".html", "text/html; charset=utf-8"},
                                                          {".csv", "text/csv; charset=utf-8"},
                                                          {".jsonl", "text/plain; charset=utf-8"},
                                                          {".json", "application/json"},
                                                          {".yaml", "text/plain; charset=utf-8"},
                                                          {".txt", "text/plain; charset=utf-8"},
                                                          {".png", "image/png"},
                                                          {".dfq", "text/plain; charset=utf-8"}};
    const auto t = types.find(file.extension().string());
    return t == types.end() ? "application/octet-stream" : t->second;
}

struct Server::Impl {
    ServerConfig config;
    ViewSource view;     // the status page's
    TextSource metrics;  // or the metrics endpoint's
    httplib::Server http;
    std::thread listener;
    int port = 0;

    void read_only();
    void routes();
    static core::Result<std::unique_ptr<Server>> listen(std::unique_ptr<Impl> impl,
                                                        const std::string& what);
};

void Server::Impl::read_only() {
    http.set_pre_routing_handler([](const httplib::Request& req, httplib::Response& res) {
        res.set_header("X-Content-Type-Options", "nosniff");
        res.set_header("Content-Security-Policy", kPolicy);
        if (req.method == "GET" || req.method == "HEAD")
            return httplib::Server::HandlerResponse::Unhandled;
        res.status = 405;  // read-only: no method that could change anything
        res.set_header("Allow", "GET, HEAD");
        return httplib::Server::HandlerResponse::Handled;
    });
}

void Server::Impl::routes() {
    read_only();
    http.Get("/", [this](const httplib::Request&, httplib::Response& res) {
        res.set_header("Cache-Control", "no-cache");
        res.set_content(render_status_page(view()), "text/html; charset=utf-8");
    });
    http.Get("/status.json", [this](const httplib::Request&, httplib::Response& res) {
        res.set_header("Cache-Control", "no-cache");
        res.set_content(render_status_json(view()), "application/json");
    });
    http.Get(R"(/pictures/(\d+)/([A-Za-z0-9_-]+)\.png)",
             [this](const httplib::Request& req, httplib::Response& res) {
                 serve_picture(view(), req, res);
             });
    for (const auto& root : config.roots)
        http.Get("/" + root.name + "(?:/(.*))?",
                 [root](const httplib::Request& req, httplib::Response& res) {
                     serve_root(root, req, res);
                 });
}

Server::Server(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Server::~Server() {
    impl_->http.stop();
    if (impl_->listener.joinable()) impl_->listener.join();
}

core::Result<std::unique_ptr<Server>> Server::start(const ServerConfig& config, ViewSource view) {
    auto impl = std::make_unique<Impl>();
    impl->config = config;
    impl->view = std::move(view);
    impl->routes();
    return Impl::listen(std::move(impl), "status page");
}

core::Result<std::unique_ptr<Server>> Server::start_metrics(const ServerConfig& config,
                                                            TextSource metrics) {
    auto impl = std::make_unique<Impl>();
    impl->config = config;
    impl->metrics = std::move(metrics);
    impl->read_only();
    impl->http.Get("/metrics", [raw = impl.get()](const httplib::Request&, httplib::Response& res) {
        res.set_header("Cache-Control", "no-cache");
        res.set_content(raw->metrics(), "text/plain; version=0.0.4; charset=utf-8");
    });
    return Impl::listen(std::move(impl), "metrics endpoint");
}

core::Result<std::unique_ptr<Server>> Server::Impl::listen(std::unique_ptr<Impl> impl,
                                                           const std::string& what) {
    const ServerConfig& config = impl->config;
    auto& http = impl->http;
    http.new_task_queue = [c = config] { return new BoundedPool(c.threads, c.queue); };
    const auto timeout = std::chrono::milliseconds(config.read_timeout_ms);
    http.set_read_timeout(timeout);
    http.set_write_timeout(timeout);
    http.set_keep_alive_timeout(2);
    http.set_keep_alive_max_count(20);
    http.set_payload_max_length(64 * 1024);
    // httplib's default also sets SO_REUSEPORT, with which a second process binds the same port
    // and takes a share of the connections; SO_REUSEADDR alone lets a restart bind at once.
    http.set_socket_options([](int sock) {
        int yes = 1;
        ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    });
    impl->port = config.port == 0 ? http.bind_to_any_port(config.bind_address)
                 : http.bind_to_port(config.bind_address, config.port) ? config.port
                                                                       : -1;
    if (impl->port < 0)
        return core::make_error(what + ": cannot listen on " + config.bind_address + ":" +
                                std::to_string(config.port));
    Impl* raw = impl.get();
    impl->listener = std::thread([raw] { raw->http.listen_after_bind(); });
    // httplib 0.11.4's stop() does nothing before the listener runs (it would then accept for
    // ever): serving when start returns, so that the destructor can always stop it.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (!http.is_running() && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    return std::unique_ptr<Server>(new Server(std::move(impl)));
}

int Server::port() const { return impl_->port; }

std::string Server::url() const {
    const std::string& a = impl_->config.bind_address;
    const bool v6 = a.find(':') != std::string::npos;
    return "http://" + (v6 ? "[" + a + "]" : a) + ":" + std::to_string(impl_->port) + "/";
}

}  // namespace hotgauge::web
