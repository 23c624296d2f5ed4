#include "number_rows.hpp"

#include <cstdlib>
#include <fstream>
#include <vector>

namespace trailnav::eval {

std::string read_number_rows(const std::string& path, std::size_t min_fields, std::size_t max_fields,
                             std::string_view expected,
                             const std::function<std::string(int line, std::span<const double> fields)>& row) {
  std::ifstream in(path);
  if (!in) return path + ": cannot read";
  std::string line;
  std::vector<double> fields;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    fields.clear();
    bool numbers = true;
    const char* p = line.c_str();
    while (*p != '\0' && numbers) {
      while (*p == ' ' || *p == '\t') ++p;
      char* end = nullptr;
      const double v = std::strtod(p, &end);
      numbers = end != p;
      if (!numbers) break;
      fields.push_back(v);
      p = end;
      while (*p == ' ' || *p == '\t') ++p;
      if (*p == ',') ++p;
    }
    if (!numbers && number == 1 && fields.empty()) continue;  // a header
    if (!numbers || fields.size() < min_fields || fields.size() > max_fields)
      return path + ":" + std::to_string(number) + ": expected " + std::string(expected);
    if (std::string e = row(number, fields); !e.empty()) return path + ":" + std::to_string(number) + ": " + e;
  }
  return "";
}

}  // namespace trailnav::eval
