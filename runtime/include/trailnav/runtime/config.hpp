// Configuration files: YAML read once at start-up into plain structs.
//
// A ConfigNode wraps one YAML mapping and remembers every key the program
// asks about, so that after reading a section `reject_unknown_keys()` can name
// a misspelt key with its line and list the keys that are allowed. Every
// error names the file, the line and the full key path, and says what is
// allowed; nothing falls back silently to a default for a bad value.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <memory>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include <yaml-cpp/yaml.h>

namespace trailnav {

// Thrown while reading; the boundary functions turn it into an error value.
class ConfigError : public std::runtime_error {
 public:
  ConfigError(const std::string& file, int line, const std::string& key, const std::string& problem);
  const std::string& file() const noexcept { return file_; }
  int line() const noexcept { return line_; }
  const std::string& key() const noexcept { return key_; }

 private:
  std::string file_;
  int line_;
  std::string key_;
};

class ConfigNode {
 public:
  // Parses a file; syntax errors are ConfigErrors with the file and line.
  static ConfigNode load_file(const std::string& path);
  // Parses text; `source_name` stands for the file name in errors.
  static ConfigNode parse(const std::string& text, const std::string& source_name);

  const std::string& file() const noexcept { return file_; }
  const std::string& path() const noexcept { return path_; }  // e.g. "runtime.tasks[2]"
  int line() const noexcept;                                  // 1-based; 0 if unknown

  bool has(std::string_view key) const;
  // Present and a mapping (a key may take either a mapping or a list).
  bool is_map(std::string_view key) const;

  // Sub-mapping; `optional_map` returns nullopt when the key is absent.
  ConfigNode map(std::string_view key) const;
  std::optional<ConfigNode> optional_map(std::string_view key) const;
  // A sequence of mappings.
  std::vector<ConfigNode> map_list(std::string_view key) const;
  std::vector<ConfigNode> optional_map_list(std::string_view key) const;

  // Scalars. The required forms fail when the key is absent.
  std::string string(std::string_view key) const;
  std::string string(std::string_view key, const std::string& fallback) const;
  bool boolean(std::string_view key) const;
  bool boolean(std::string_view key, bool fallback) const;
  double number(std::string_view key, double min, double max) const;
  double number(std::string_view key, double min, double max, double fallback) const;
  std::int64_t integer(std::string_view key, std::int64_t min, std::int64_t max) const;
  std::int64_t integer(std::string_view key, std::int64_t min, std::int64_t max, std::int64_t fallback) const;
  // One of `choices`.
  std::string choice(std::string_view key, std::initializer_list<std::string_view> choices) const;
  std::string choice(std::string_view key, std::initializer_list<std::string_view> choices,
                     const std::string& fallback) const;
  std::vector<double> number_list(std::string_view key, double min, double max) const;
  std::vector<std::string> string_list(std::string_view key) const;
  // A list of rows of exactly `columns` numbers each, e.g. points [[x, y], ...].
  std::vector<std::vector<double>> number_rows(std::string_view key, std::size_t columns, double min,
                                               double max) const;

  // Fails on the first key of this mapping that was never asked about.
  void reject_unknown_keys() const;

  // Fails with this file, the line of `key` (or of the mapping) and `problem`.
  [[noreturn]] void fail(std::string_view key, const std::string& problem) const;

 private:
  ConfigNode(YAML::Node node, std::string file, std::string path);
  YAML::Node value_of(std::string_view key) const;  // also marks the key as asked
  std::string key_path(std::string_view key) const;
  int line_of(const YAML::Node& node) const noexcept;
  void require_scalar(std::string_view key, const YAML::Node& value, const char* expected) const;
  double parse_number(const YAML::Node& value, const std::string& key_for_error, int line, double min,
                      double max) const;

  YAML::Node node_;
  std::string file_;
  std::string path_;
  std::shared_ptr<std::set<std::string, std::less<>>> asked_;
};

}  // namespace trailnav
