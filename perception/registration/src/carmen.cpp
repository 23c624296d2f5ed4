#include "trailnav/perception/registration/carmen.hpp"

#include <zlib.h>

#include <charconv>
#include <cmath>

namespace trailnav::perception::registration {

namespace {
constexpr double kMaxRange = 1e5;  // m: beyond it a range is not a laser's (and not a float's to hold safely)

// The next space-separated field; empty at the end.
std::string_view next(std::string_view& s) {
  std::size_t i = 0;
  while (i < s.size() && (s[i] == ' ' || s[i] == '\t' || s[i] == '\r' || s[i] == '\n')) ++i;
  std::size_t j = i;
  while (j < s.size() && s[j] != ' ' && s[j] != '\t' && s[j] != '\r' && s[j] != '\n') ++j;
  const std::string_view f = s.substr(i, j - i);
  s.remove_prefix(j);
  return f;
}
bool number(std::string_view f, double& v) {
  if (f.empty()) return false;
  const auto r = std::from_chars(f.data(), f.data() + f.size(), v);
  return r.ec == std::errc() && r.ptr == f.data() + f.size() && std::isfinite(v);
}
}  // namespace

std::string parse_flaser(std::string_view line, LaserScan2& out, std::size_t max_beams) {
  std::string_view s = line;
  if (next(s) != "FLASER") return "not FLASER";
  double n = 0.0;
  const std::string_view count_field = next(s);
  if (!number(count_field, n) || n < 2.0 || n != std::floor(n)) return "FLASER: the beam count is not a whole number of 2 or more";
  if (n > static_cast<double>(max_beams)) {
    return "FLASER: " + std::string(count_field) + " beams, at most " + std::to_string(max_beams);
  }
  const auto count = static_cast<std::size_t>(n);
  out.ranges.clear();
  for (std::size_t i = 0; i < count; ++i) {
    double r = 0.0;
    if (!number(next(s), r)) return "FLASER: range " + std::to_string(i + 1) + " of " + std::to_string(count) + " is missing or not a number";
    if (r < 0.0) return "FLASER: range " + std::to_string(i + 1) + " is negative";
    if (r > kMaxRange) return "FLASER: range " + std::to_string(i + 1) + " is beyond 100 km";
    out.ranges.push_back(static_cast<float>(r));
  }
  double v[7];
  const char* names[7] = {"x", "y", "theta", "odom_x", "odom_y", "odom_theta", "ipc_timestamp"};
  for (int k = 0; k < 7; ++k) {
    if (!number(next(s), v[k])) return std::string("FLASER: ") + names[k] + " is missing or not a number";
  }
  out.pose = {v[0], v[1], v[2]};
  out.odometry = {v[3], v[4], v[5]};
  out.timestamp = v[6];
  return "";
}

std::size_t scan_points(const LaserScan2& scan, float max_range, float min_range, std::vector<Point>& out) noexcept {
  const std::size_t n = scan.ranges.size();
  if (n < 2) return 0;
  // 181 and 361 beams: both ends included (n − 1 steps over 180°); 180 and
  // 360: 180°/n steps from −90°.
  const double step = (n % 2 == 1 ? M_PI / static_cast<double>(n - 1) : M_PI / static_cast<double>(n));
  std::size_t no_room = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const float r = scan.ranges[i];
    if (!(r < max_range) || r < min_range) continue;
    if (out.size() == out.capacity()) {
      ++no_room;
      continue;
    }
    const double a = -M_PI / 2.0 + static_cast<double>(i) * step;
    out.emplace_back(static_cast<float>(static_cast<double>(r) * std::cos(a)),
                     static_cast<float>(static_cast<double>(r) * std::sin(a)), 0.0f);
  }
  return no_room;
}

FlaserLog read_flaser_log(const std::string& path, long from, long to) {
  FlaserLog log;
  gzFile f = gzopen(path.c_str(), "rb");
  if (f == nullptr) {
    log.error = "cannot open " + path;
    return log;
  }
  std::vector<char> line(1 << 16);
  long number = 0, index = 0;
  while (gzgets(f, line.data(), static_cast<int>(line.size())) != nullptr) {
    ++number;
    const std::string_view text(line.data());
    if (text.rfind("FLASER", 0) != 0) continue;
    LaserScan2 s;
    const std::string error = parse_flaser(text, s);
    if (!error.empty()) {
      if (log.first_error.empty()) log.first_error = "line " + std::to_string(number) + ": " + error;
      ++log.refused;
      continue;
    }
    if (index >= from) log.scans.push_back(std::move(s));
    ++index;
    if (to >= 0 && index > to) break;
  }
  gzclose(f);
  return log;
}

Eigen::Isometry3d to_isometry(const Pose2& p) noexcept {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::AngleAxisd(p.theta, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  t.translation() = Eigen::Vector3d(p.x, p.y, 0.0);
  return t;
}

Pose2 to_pose2(const Eigen::Isometry3d& t) noexcept {
  return {t.translation().x(), t.translation().y(), std::atan2(t.linear()(1, 0), t.linear()(0, 0))};
}

}  // namespace trailnav::perception::registration
