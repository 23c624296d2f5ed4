#include "trailnav/runtime/config.hpp"

#include <cmath>
#include <fstream>
#include <sstream>
#include <utility>
#include <vector>

namespace trailnav {
namespace {

std::string format_error(const std::string& file, int line, const std::string& key, const std::string& problem) {
  std::string out = file;
  if (line > 0) out += ":" + std::to_string(line);
  out += ": ";
  if (!key.empty()) out += "'" + key + "': ";
  out += problem;
  return out;
}

std::string format_number(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

std::string join(std::initializer_list<std::string_view> items) {
  std::string out;
  for (std::string_view item : items) {
    if (!out.empty()) out += ", ";
    out += item;
  }
  return out;
}

}  // namespace

ConfigError::ConfigError(const std::string& file, int line, const std::string& key, const std::string& problem)
    : std::runtime_error(format_error(file, line, key, problem)), file_(file), line_(line), key_(key) {}

ConfigNode::ConfigNode(YAML::Node node, std::string file, std::string path)
    : node_(std::move(node)),
      file_(std::move(file)),
      path_(std::move(path)),
      asked_(std::make_shared<std::set<std::string, std::less<>>>()) {}

ConfigNode ConfigNode::load_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ConfigError(path, 0, "", "cannot open the configuration file");
  std::stringstream text;
  text << in.rdbuf();
  return parse(text.str(), path);
}

namespace {

// YAML says a mapping's keys are unique; yaml-cpp keeps the first of two and
// says nothing, so a setting written twice would be silently dropped.
void refuse_duplicate_keys(const YAML::Node& node, const std::string& source, const std::string& path) {
  if (node.IsMap()) {
    std::vector<std::pair<std::string, int>> seen;
    for (const auto& kv : node) {
      const std::string key = kv.first.IsScalar() ? kv.first.Scalar() : std::string();
      const int line = kv.first.Mark().line >= 0 ? kv.first.Mark().line + 1 : 0;
      const std::string here = path.empty() ? key : path + "." + key;
      for (const auto& [k, l] : seen) {
        if (k == key && kv.first.IsScalar()) {
          throw ConfigError(source, line, here,
                            "given twice (first at line " + std::to_string(l) + "): give each setting once");
        }
      }
      seen.emplace_back(key, line);
      refuse_duplicate_keys(kv.second, source, here);
    }
  } else if (node.IsSequence()) {
    for (std::size_t i = 0; i < node.size(); ++i) refuse_duplicate_keys(node[i], source, path + "[" + std::to_string(i) + "]");
  }
}

}  // namespace

ConfigNode ConfigNode::parse(const std::string& text, const std::string& source_name) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(source_name, e.mark.line + 1, "", "YAML syntax error: " + e.msg);
  }
  if (root.IsNull()) root = YAML::Node(YAML::NodeType::Map);
  if (!root.IsMap()) throw ConfigError(source_name, 1, "", "the file must be a YAML mapping of sections");
  refuse_duplicate_keys(root, source_name, "");
  return ConfigNode(root, source_name, "");
}

int ConfigNode::line_of(const YAML::Node& node) const noexcept {
  const YAML::Mark mark = node.Mark();
  return mark.line >= 0 ? mark.line + 1 : 0;
}

int ConfigNode::line() const noexcept { return line_of(node_); }

std::string ConfigNode::key_path(std::string_view key) const {
  if (path_.empty()) return std::string(key);
  return path_ + "." + std::string(key);
}

void ConfigNode::fail(std::string_view key, const std::string& problem) const {
  int line = this->line();
  if (!key.empty()) {
    for (const auto& item : node_) {
      if (item.first.Scalar() == key) {
        line = line_of(item.first);
        break;
      }
    }
  }
  throw ConfigError(file_, line, key.empty() ? path_ : key_path(key), problem);
}

YAML::Node ConfigNode::value_of(std::string_view key) const {
  asked_->emplace(key);
  const YAML::Node& const_node = node_;
  for (const auto& item : const_node) {
    if (item.first.Scalar() == key) return item.second;
  }
  return YAML::Node(YAML::NodeType::Undefined);
}

bool ConfigNode::has(std::string_view key) const {
  const YAML::Node value = value_of(key);
  return value.IsDefined() && !value.IsNull();
}

bool ConfigNode::is_map(std::string_view key) const {
  const YAML::Node value = value_of(key);
  return value.IsDefined() && value.IsMap();
}

void ConfigNode::require_scalar(std::string_view key, const YAML::Node& value, const char* expected) const {
  if (!value.IsScalar()) fail(key, std::string("expected ") + expected + ", found a " + (value.IsMap() ? "mapping" : "sequence"));
}

ConfigNode ConfigNode::map(std::string_view key) const {
  const YAML::Node value = value_of(key);
  if (!value.IsDefined() || value.IsNull()) fail("", "missing required section '" + key_path(key) + "'");
  if (!value.IsMap()) fail(key, "expected a mapping (a section of 'key: value' lines)");
  return ConfigNode(value, file_, key_path(key));
}

std::optional<ConfigNode> ConfigNode::optional_map(std::string_view key) const {
  if (!has(key)) return std::nullopt;
  return map(key);
}

std::vector<ConfigNode> ConfigNode::map_list(std::string_view key) const {
  const YAML::Node value = value_of(key);
  if (!value.IsDefined() || value.IsNull()) fail("", "missing required list '" + key_path(key) + "'");
  if (!value.IsSequence()) fail(key, "expected a list ('- ' items)");
  std::vector<ConfigNode> out;
  std::size_t index = 0;
  for (const auto& item : value) {
    const std::string item_path = key_path(key) + "[" + std::to_string(index++) + "]";
    if (!item.IsMap()) throw ConfigError(file_, line_of(item), item_path, "expected a mapping as list item");
    out.push_back(ConfigNode(item, file_, item_path));
  }
  return out;
}

std::vector<ConfigNode> ConfigNode::optional_map_list(std::string_view key) const {
  if (!has(key)) return {};
  return map_list(key);
}

std::string ConfigNode::string(std::string_view key) const {
  const YAML::Node value = value_of(key);
  if (!value.IsDefined() || value.IsNull()) fail("", "missing required key '" + key_path(key) + "' (a string)");
  require_scalar(key, value, "a string");
  return value.Scalar();
}

std::string ConfigNode::string(std::string_view key, const std::string& fallback) const {
  return has(key) ? string(key) : fallback;
}

bool ConfigNode::boolean(std::string_view key) const {
  const YAML::Node value = value_of(key);
  if (!value.IsDefined() || value.IsNull()) fail("", "missing required key '" + key_path(key) + "' (true or false)");
  require_scalar(key, value, "true or false");
  const std::string& s = value.Scalar();
  if (s == "true") return true;
  if (s == "false") return false;
  fail(key, "'" + s + "' is not a boolean; allowed: true, false");
}

bool ConfigNode::boolean(std::string_view key, bool fallback) const { return has(key) ? boolean(key) : fallback; }

double ConfigNode::parse_number(const YAML::Node& value, const std::string& key_for_error, int line, double min,
                                double max) const {
  const std::string range = "[" + format_number(min) + ", " + format_number(max) + "]";
  const std::string where = key_path(key_for_error);
  if (!value.IsScalar()) throw ConfigError(file_, line, where, "expected a number in " + range);
  const std::string& s = value.Scalar();
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size() || s.empty() || !std::isfinite(v)) {
    throw ConfigError(file_, line, where, "'" + s + "' is not a number; allowed: a number in " + range);
  }
  if (v < min || v > max) throw ConfigError(file_, line, where, format_number(v) + " is out of range; allowed: " + range);
  return v;
}

double ConfigNode::number(std::string_view key, double min, double max) const {
  const YAML::Node value = value_of(key);
  if (!value.IsDefined() || value.IsNull()) {
    fail("", "missing required key '" + key_path(key) + "' (a number in [" + format_number(min) + ", " +
                 format_number(max) + "])");
  }
  return parse_number(value, std::string(key), line_of(value), min, max);
}

double ConfigNode::number(std::string_view key, double min, double max, double fallback) const {
  return has(key) ? number(key, min, max) : fallback;
}

std::int64_t ConfigNode::integer(std::string_view key, std::int64_t min, std::int64_t max) const {
  const YAML::Node value = value_of(key);
  const std::string range = "[" + std::to_string(min) + ", " + std::to_string(max) + "]";
  if (!value.IsDefined() || value.IsNull()) fail("", "missing required key '" + key_path(key) + "' (an integer in " + range + ")");
  require_scalar(key, value, "an integer");
  const std::string& s = value.Scalar();
  std::size_t used = 0;
  long long v = 0;
  try {
    v = std::stoll(s, &used, 10);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size() || s.empty()) fail(key, "'" + s + "' is not an integer; allowed: an integer in " + range);
  if (v < min || v > max) fail(key, std::to_string(v) + " is out of range; allowed: " + range);
  return v;
}

std::int64_t ConfigNode::integer(std::string_view key, std::int64_t min, std::int64_t max, std::int64_t fallback) const {
  return has(key) ? integer(key, min, max) : fallback;
}

std::string ConfigNode::choice(std::string_view key, std::initializer_list<std::string_view> choices) const {
  const YAML::Node value = value_of(key);
  if (!value.IsDefined() || value.IsNull()) fail("", "missing required key '" + key_path(key) + "' (one of: " + join(choices) + ")");
  require_scalar(key, value, "a word");
  const std::string& s = value.Scalar();
  for (std::string_view c : choices) {
    if (s == c) return s;
  }
  fail(key, "'" + s + "' is not allowed; allowed: " + join(choices));
}

std::string ConfigNode::choice(std::string_view key, std::initializer_list<std::string_view> choices,
                               const std::string& fallback) const {
  return has(key) ? choice(key, choices) : fallback;
}

std::vector<std::string> ConfigNode::string_list(std::string_view key) const {
  const YAML::Node value = value_of(key);
  if (!value.IsDefined() || value.IsNull()) fail("", "missing required key '" + key_path(key) + "' (a list of strings)");
  if (!value.IsSequence()) fail(key, "expected a list of strings, e.g. [track, path]");
  std::vector<std::string> out;
  std::size_t index = 0;
  for (const auto& item : value) {
    const std::string item_key = std::string(key) + "[" + std::to_string(index++) + "]";
    if (!item.IsScalar() || item.Scalar().empty()) {
      throw ConfigError(file_, line_of(item), key_path(item_key), "expected a non-empty string");
    }
    out.push_back(item.Scalar());
  }
  return out;
}

std::vector<double> ConfigNode::number_list(std::string_view key, double min, double max) const {
  const YAML::Node value = value_of(key);
  if (!value.IsDefined() || value.IsNull()) fail("", "missing required key '" + key_path(key) + "' (a list of numbers)");
  if (!value.IsSequence()) fail(key, "expected a list of numbers, e.g. [1.0, 2.0]");
  std::vector<double> out;
  std::size_t index = 0;
  for (const auto& item : value) {
    const std::string item_key = std::string(key) + "[" + std::to_string(index++) + "]";
    out.push_back(parse_number(item, item_key, line_of(item), min, max));
  }
  return out;
}

std::vector<std::vector<double>> ConfigNode::number_rows(std::string_view key, std::size_t columns, double min,
                                                        double max) const {
  const YAML::Node value = value_of(key);
  const std::string shape = "a list of [" + std::to_string(columns) + " numbers] rows, e.g. [[0, 0], [10, 5]]";
  if (!value.IsDefined() || value.IsNull()) fail("", "missing required key '" + key_path(key) + "' (" + shape + ")");
  if (!value.IsSequence()) fail(key, "expected " + shape);
  std::vector<std::vector<double>> out;
  std::size_t index = 0;
  for (const auto& row : value) {
    const std::string row_key = std::string(key) + "[" + std::to_string(index++) + "]";
    if (!row.IsSequence() || row.size() != columns) {
      throw ConfigError(file_, line_of(row), key_path(row_key), "expected " + std::to_string(columns) + " numbers");
    }
    std::vector<double> numbers;
    std::size_t column = 0;
    for (const auto& item : row) {
      numbers.push_back(parse_number(item, row_key + "[" + std::to_string(column++) + "]", line_of(item), min, max));
    }
    out.push_back(std::move(numbers));
  }
  return out;
}

void ConfigNode::reject_unknown_keys() const {
  for (const auto& item : node_) {
    const std::string& key = item.first.Scalar();
    if (asked_->find(key) != asked_->end()) continue;
    std::string allowed;
    for (const std::string& k : *asked_) allowed += (allowed.empty() ? "" : ", ") + k;
    throw ConfigError(file_, line_of(item.first), key_path(key),
                      "unknown key; allowed here: " + (allowed.empty() ? std::string("(none)") : allowed));
  }
}

}  // namespace trailnav
