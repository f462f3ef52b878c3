#pragma once
// Strict YAML reading for configs and recipes: every error names file:line and the key, and an
// unknown key is an error (typos must not pass silently). Used only by the readers of YAML files;
// modules take plain structs.
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <array>
#include <filesystem>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "hotgauge/core/result.hpp"
#include "hotgauge/io/bytes.hpp"

namespace hotgauge::io {

// Thrown inside a reader, caught at its entry point and turned into a core::Error.
struct YamlError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// Where a syntax error in `text` is: the line (1-based) and what yaml-cpp says. An unclosed '['
// or '{' is reported at the line it was opened on (yaml-cpp names the line where it gave up
// looking for its end, one or more later), with a note that says so.
struct YamlSyntaxError {
    int line = 0;  // 0: yaml-cpp gave no place
    int column = 0;
    std::string message;
};
YamlSyntaxError yaml_syntax_error(std::string_view text, const YAML::Exception& e);

class YamlReader {
  public:
    // Reads the file `file` when load() is called.
    explicit YamlReader(std::string file) : file_(std::move(file)) {}
    // `text` as the file named `file` (the caller keeps it alive); existing() asks `exists`.
    YamlReader(std::string file, std::string_view text, PathExists exists = exists_on_disk)
        : file_(std::move(file)), text_(text), given_(true), exists_(std::move(exists)) {}
    YamlReader(const YamlReader&) = delete;  // text_ may point into read_
    YamlReader& operator=(const YamlReader&) = delete;

    // Parses the text (read from the file first when none was given); throws
    // YamlError("file:line: ...") on I/O or syntax errors.
    YAML::Node load() const;

    // `path` (named by `node`) must exist; one the filesystem cannot look at (a name too long, a
    // symlink loop, no permission) fails at `node` with the reason, as a missing one does.
    std::filesystem::path existing(const YAML::Node& node, const std::string& what,
                                   const std::filesystem::path& path) const;

    // "file:line: " for a node (1-based line).
    std::string where(const YAML::Node& node) const;

    // `node` must be a mapping whose keys are all in `allowed`; `what` names it in messages.
    void expect_map(const YAML::Node& node, const std::string& what,
                    std::initializer_list<const char*> allowed) const;
    // A required child; missing -> "file:line: <what>: missing key 'key'".
    YAML::Node require(const YAML::Node& map, const std::string& what, const char* key) const;

    double number(const YAML::Node& node, const std::string& what) const;
    std::int64_t integer(const YAML::Node& node, const std::string& what) const;
    bool boolean(const YAML::Node& node, const std::string& what) const;
    std::string string(const YAML::Node& node, const std::string& what) const;
    std::vector<std::string> strings(const YAML::Node& node, const std::string& what) const;
    std::vector<double> numbers(const YAML::Node& node, const std::string& what,
                                std::size_t expected_size = 0) const;

    // A 4×4 rigid transform, row-major: proper rotation, last row [0, 0, 0, 1].
    Eigen::Isometry3d isometry(const YAML::Node& node, const std::string& what) const;
    // A 3×3 proper rotation (orthonormal, det +1 within 1e-6).
    Eigen::Matrix3d rotation(const YAML::Node& node, const std::string& what) const;

    // Runs a reader body; YamlError and yaml-cpp exceptions become an Error naming file:line, any
    // other exception one naming the file.
    template <class T, class Body>
    core::Result<T> guarded(Body&& body) const {
        try {
            return body();
        } catch (const YamlError& e) {
            return core::make_error(e.what());
        } catch (const YAML::Exception& e) {
            return core::make_error(file_ + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg);
        } catch (const std::exception& e) {  // filesystem_error, bad_alloc: never escapes
            return core::make_error(file_ + ": " + e.what());
        }
    }

    // Shorthands for optional keys with defaults.
    double number_or(const YAML::Node& map, const std::string& what, const char* key,
                     double fallback) const;

    [[noreturn]] void fail(const YAML::Node& node, const std::string& message) const;

    const std::string& file() const { return file_; }

  private:
    std::string file_;
    mutable std::string read_;  // the file's text, when load() read it
    mutable std::string_view text_;
    bool given_ = false;
    PathExists exists_ = exists_on_disk;
};

}  // namespace hotgauge::io
