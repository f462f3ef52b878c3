#include "hotgauge/plant/spool.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <fstream>
#include <vector>

#include "log.hpp"

namespace hotgauge::plant {
namespace {

namespace fs = std::filesystem;

using detail::log;

std::string errno_text() { return std::strerror(errno); }

// Closes a descriptor on every way out of a function.
struct Fd {
    int fd = -1;
    explicit Fd(int f) : fd(f) {}
    ~Fd() {
        if (fd >= 0) ::close(fd);
    }
    Fd(const Fd&) = delete;
    Fd& operator=(const Fd&) = delete;
};

bool write_all(int fd, std::string_view data) {
    while (!data.empty()) {
        const ssize_t n = ::write(fd, data.data(), data.size());
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return false;
        data.remove_prefix(static_cast<std::size_t>(n));
    }
    return true;
}

// A rename or a new file is durable only once its folder is synced too.
core::Result<void> sync_dir(const fs::path& dir) {
    Fd d(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
    if (d.fd < 0 || ::fsync(d.fd) != 0)
        return core::make_error(dir.string() + ": cannot sync the spool folder: " + errno_text());
    return {};
}

// The cursor file holds one decimal number; anything else reads as 0, so that a damaged cursor
// sends again rather than loses (at least once).
std::uint64_t read_cursor(const fs::path& file) {
    Fd f(::open(file.c_str(), O_RDONLY | O_CLOEXEC));
    if (f.fd < 0) return 0;
    char buf[32];
    const ssize_t n = ::read(f.fd, buf, sizeof buf);
    std::uint64_t value = 0;
    if (n <= 0 || std::from_chars(buf, buf + n, value).ec != std::errc{}) {
        log().warn("{}: unreadable acknowledgement cursor, the spool is sent again from its start",
                   file.string());
        return 0;
    }
    return value;
}

// Written to a temporary file, synced and renamed over the old one: a crash leaves either.
core::Result<void> write_small(const fs::path& dir, const char* name, const std::string& text) {
    const fs::path file = dir / name, tmp = dir / (std::string(name) + ".tmp");
    {
        Fd f(::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644));
        if (f.fd < 0 || !write_all(f.fd, text + "\n") || ::fsync(f.fd) != 0)
            return core::make_error(tmp.string() + ": cannot write: " + errno_text());
    }
    if (::rename(tmp.c_str(), file.c_str()) != 0)
        return core::make_error(file.string() + ": cannot replace: " + errno_text());
    return sync_dir(dir);
}

core::Result<void> write_cursor(const fs::path& dir, std::uint64_t cursor) {
    return write_small(dir, "spool.cursor", std::to_string(cursor));
}

}  // namespace

struct Spool::Impl {
    SpoolConfig config;
    fs::path file;  // spool.jsonl
    int fd = -1;    // spool.jsonl, read and appended to
    mutable std::mutex mutex;
    std::uint64_t size = 0;    // of spool.jsonl, as we wrote it
    std::uint64_t cursor = 0;  // acknowledged up to here
    std::uint64_t depth = 0;   // lines after the cursor
    std::uint64_t refused = 0;
    bool full = false;
    std::string error;

    ~Impl() {
        if (fd >= 0) ::close(fd);
    }

    // The line starting at offset, without its '\n'; nullopt at the end or on a read error.
    std::optional<std::string> line_at(std::uint64_t offset) const {
        std::string line;
        char buf[4096];
        while (offset < size) {
            const ssize_t n = ::pread(fd, buf, sizeof buf, static_cast<off_t>(offset));
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) return std::nullopt;
            const std::string_view chunk(buf, static_cast<std::size_t>(n));
            const auto nl = chunk.find('\n');
            line.append(chunk.substr(0, nl));
            if (nl != std::string_view::npos) return line;
            offset += static_cast<std::uint64_t>(n);
        }
        return std::nullopt;  // no newline before the end: not a whole line
    }

    // Just past the last '\n' before offset `end` (0 when there is none), read block by block
    // from the end; nullopt on a read error.
    std::optional<std::uint64_t> line_start_before(std::uint64_t end) const {
        char buf[4096];
        while (end > 0) {
            const std::uint64_t from = end > sizeof buf ? end - sizeof buf : 0;
            const auto n = static_cast<std::size_t>(end - from);
            if (::pread(fd, buf, n, static_cast<off_t>(from)) != static_cast<ssize_t>(n))
                return std::nullopt;
            if (const void* nl = ::memrchr(buf, '\n', n))
                return from + static_cast<std::uint64_t>(static_cast<const char*>(nl) - buf) + 1;
            end = from;
        }
        return 0;
    }

    core::Result<void> recover();
    core::Result<void> cut_torn_line();
    void count_depth();
};

// A last line without its '\n' is what a power cut during append() leaves: it was never
// acknowledged to the caller as durable, so it is dropped.
core::Result<void> Spool::Impl::cut_torn_line() {
    const auto last = line_start_before(size);  // after the last '\n'
    if (!last) return core::make_error(file.string() + ": cannot read: " + errno_text());
    const std::uint64_t end = *last;
    if (end == size) return {};
    if (::ftruncate(fd, static_cast<off_t>(end)) != 0 || ::fsync(fd) != 0)
        return core::make_error(file.string() +
                                ": cannot cut the incomplete last line: " + errno_text());
    log().warn("{}: cut off an incomplete last line ({} bytes without a newline)", file.string(),
               size - end);
    size = end;
    return {};
}

void Spool::Impl::count_depth() {
    depth = 0;
    char buf[65536];
    for (std::uint64_t at = cursor; at < size;) {
        const ssize_t n = ::pread(fd, buf, sizeof buf, static_cast<off_t>(at));
        if (n <= 0) break;
        for (ssize_t i = 0; i < n; ++i) depth += buf[i] == '\n';
        at += static_cast<std::uint64_t>(n);
    }
}

core::Result<void> Spool::Impl::recover() {
    struct stat st {};
    if (::fstat(fd, &st) != 0)
        return core::make_error(file.string() + ": cannot stat: " + errno_text());
    size = static_cast<std::uint64_t>(st.st_size);
    if (auto ok = cut_torn_line(); !ok) return ok;
    cursor = read_cursor(config.dir / "spool.cursor");
    // Past the end: the file was emptied after everything was acknowledged, and the crash came
    // before the cursor went back to 0 (pop() empties first, so nothing is sent twice).
    if (cursor > size) {
        log().info("{}: cursor {} past the end ({} bytes): everything was acknowledged",
                   file.string(), cursor, size);
        cursor = 0;
        if (auto ok = write_cursor(config.dir, 0); !ok) return ok;
    }
    count_depth();
    return {};
}

core::Result<std::unique_ptr<Spool>> Spool::open(const SpoolConfig& config) {
    std::error_code ec;
    fs::create_directories(config.dir, ec);
    if (ec)
        return core::make_error(config.dir.string() +
                                ": cannot create the spool folder: " + ec.message());
    auto impl = std::make_unique<Impl>();
    impl->config = config;
    impl->file = config.dir / "spool.jsonl";
    impl->fd = ::open(impl->file.c_str(), O_RDWR | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (impl->fd < 0)
        return core::make_error(impl->file.string() + ": cannot open the spool: " + errno_text());
    if (auto ok = sync_dir(config.dir); !ok) return ok.error();
    if (auto ok = impl->recover(); !ok) return ok.error();
    if (impl->depth > 0)
        log().info("{}: {} messages ({} bytes) waiting from before", impl->file.string(),
                   impl->depth, impl->size - impl->cursor);
    return std::unique_ptr<Spool>(new Spool(std::move(impl)));
}

Spool::Spool(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Spool::~Spool() = default;

core::Result<void> Spool::append(std::string_view message) {
    Impl& s = *impl_;
    std::lock_guard lock(s.mutex);
    auto refuse = [&s](std::string why) -> core::Result<void> {
        ++s.refused;
        return core::make_error(std::move(why));
    };
    if (message.find('\n') != std::string_view::npos)
        return refuse(s.file.string() + ": a message must be one line (it holds a '\\n')");
    const std::uint64_t waiting = s.size - s.cursor, line = message.size() + 1;
    if (waiting + line > s.config.max_bytes) {
        s.full = true;
        return refuse(s.config.dir.string() + ": spool full: " + std::to_string(waiting) +
                      " bytes waiting + " + std::to_string(line) + " would exceed the limit of " +
                      std::to_string(s.config.max_bytes) + " bytes (broker unreachable?)");
    }
    std::string bytes(message);
    bytes += '\n';
    if (!write_all(s.fd, bytes) || ::fsync(s.fd) != 0) {
        s.error = s.file.string() + ": cannot append: " + errno_text();
        // A partial line would be cut at the next open(); cut it now so the next append starts
        // on a line boundary.
        if (::ftruncate(s.fd, static_cast<off_t>(s.size)) != 0)
            log().error("{}: cannot undo a failed append: {}", s.file.string(), errno_text());
        return refuse(s.error);
    }
    s.size += line;
    ++s.depth;
    s.full = false;
    s.error.clear();
    return {};
}

std::optional<std::string> Spool::front() const {
    std::lock_guard lock(impl_->mutex);
    return impl_->line_at(impl_->cursor);
}

core::Result<void> Spool::pop() {
    Impl& s = *impl_;
    std::lock_guard lock(s.mutex);
    const auto line = s.line_at(s.cursor);
    if (!line) return core::make_error(s.file.string() + ": pop() on an empty spool");
    const std::uint64_t next = s.cursor + line->size() + 1;
    if (next < s.size) {
        if (auto ok = write_cursor(s.config.dir, next); !ok) return ok;
        s.cursor = next;
    } else {
        // All acknowledged: the last message kept aside, then the file emptied, then the
        // cursor. A crash between the last two leaves a cursor past the end, which open() reads
        // as 0 of an empty file: nothing again.
        if (auto ok = write_small(s.config.dir, "spool.last", *line); !ok) return ok;
        if (::ftruncate(s.fd, 0) != 0)
            return core::make_error(s.file.string() + ": cannot empty the spool: " + errno_text());
        s.size = s.cursor = s.depth = 0;
        if (::fsync(s.fd) != 0)
            return core::make_error(s.file.string() +
                                    ": cannot sync the emptied spool: " + errno_text());
        return write_cursor(s.config.dir, 0);
    }
    --s.depth;
    return {};
}

std::optional<std::string> Spool::last_appended() const {
    std::lock_guard lock(impl_->mutex);
    const Impl& s = *impl_;
    if (s.size > 0) {  // the line that ends at the end of the file (before its '\n')
        const auto start = s.line_start_before(s.size - 1);
        return start ? s.line_at(*start) : std::nullopt;
    }
    std::ifstream kept(s.config.dir / "spool.last");
    std::string line;
    if (kept && std::getline(kept, line) && !line.empty()) return line;
    return std::nullopt;
}

core::Result<void> Spool::start_after(std::string_view message) {
    if (last_appended()) return {};
    std::lock_guard lock(impl_->mutex);
    return write_small(impl_->config.dir, "spool.last", std::string(message));
}

SpoolState Spool::state() const {
    std::lock_guard lock(impl_->mutex);
    const Impl& s = *impl_;
    return SpoolState{s.depth, s.size - s.cursor, s.refused, s.full, s.error};
}

const std::filesystem::path& Spool::dir() const { return impl_->config.dir; }

}  // namespace hotgauge::plant
