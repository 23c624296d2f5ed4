#include "trailnav/perception/registration/station_file.hpp"

#include <cmath>

#include "trailnav/runtime/le_bytes.hpp"
#include "trailnav/runtime/sealed_file.hpp"

namespace trailnav::perception::registration {

namespace {

constexpr char kMagic[8] = {'T', 'N', 'S', 'T', 'A', 'T', 'N', '\0'};

void put_string(std::vector<std::uint8_t>& out, const std::string& s) {
  le::put_u16(out, static_cast<std::uint16_t>(s.size()));
  out.insert(out.end(), s.begin(), s.end());
}

bool get_string(le::Reader& in, std::string& s, std::size_t max) {
  std::uint16_t n = 0;
  return in.u16(n) && n <= max && in.bytes(n, s);
}


}  // namespace

std::vector<std::uint8_t> serialize_station(const StationFile& s) {
  std::vector<std::uint8_t> out = sealed::begin(kMagic, kStationFileVersion);
  put_string(out, s.name);
  le::put_u32(out, static_cast<std::uint32_t>(s.bodies.size()));
  for (const StationBodyFile& b : s.bodies) {
    put_string(out, b.name);
    le::put_u32(out, static_cast<std::uint32_t>(b.polygon.size()));
    for (const Eigen::Vector2d& c : b.polygon) {
      le::put_f64(out, c.x());
      le::put_f64(out, c.y());
    }
    le::put_u32(out, static_cast<std::uint32_t>(b.points.size()));
    for (const Point& p : b.points) {
      le::put_f32(out, p.x());
      le::put_f32(out, p.y());
      le::put_f32(out, p.z());
    }
  }
  sealed::seal(out);
  return out;
}

LoadedStation parse_station(std::span<const std::uint8_t> bytes, std::string_view what) {
  LoadedStation r;
  const std::string w(what);
  auto fail = [&](const std::string& e) {
    r.error = w + ": " + e;
    return r;
  };
  const sealed::Opened opened = sealed::open(bytes, kMagic, "station file");
  if (!opened.problem.empty()) return fail(opened.problem);
  if (opened.version != kStationFileVersion) {
    return fail("version " + std::to_string(opened.version) + ", this trailnav reads version " +
                std::to_string(kStationFileVersion) + " (teach the station again)");
  }
  if (!opened.checksum_ok) return fail("the checksum does not match: the file is damaged or cut short");
  le::Reader in(opened.body);
  StationFile s;
  if (!get_string(in, s.name, kStationMaxName)) return fail("the station's name is cut short or longer than 64 bytes");
  std::uint32_t nb = 0;
  if (!in.u32(nb) || nb < 1 || nb > kStationMaxBodies) return fail("bodies: 1 to 64 (the surroundings and the objects)");
  for (std::uint32_t k = 0; k < nb; ++k) {
    StationBodyFile b;
    const std::string which = "body " + std::to_string(k);
    if (!get_string(in, b.name, kStationMaxName) || b.name.empty()) return fail(which + ": a name of 1 to 64 bytes");
    std::uint32_t corners = 0;
    if (!in.u32(corners)) return fail(which + " (" + b.name + "): cut short");
    if (k == 0 ? corners != 0 : (corners < 3 || corners > kStationMaxCorners)) {
      return fail(which + " (" + b.name + "): " + std::to_string(corners) + " polygon corners; the surroundings have none, "
                  "an object 3 to 1024");
    }
    if (in.left() / 16 < corners) return fail(which + " (" + b.name + "): its polygon is cut short");
    for (std::uint32_t c = 0; c < corners; ++c) {
      double x = 0.0, y = 0.0;
      in.f64(x);
      in.f64(y);
      if (!std::isfinite(x) || !std::isfinite(y)) return fail(which + " (" + b.name + "): a polygon corner is not finite");
      b.polygon.emplace_back(x, y);
    }
    std::uint32_t n = 0;
    if (!in.u32(n) || n > kStationMaxPoints) return fail(which + " (" + b.name + "): at most 4,194,304 points");
    if (in.left() / 12 < n) return fail(which + " (" + b.name + "): its points are cut short");
    b.points.reserve(n);
    for (std::uint32_t i = 0; i < n; ++i) {
      float x = 0.0f, y = 0.0f, z = 0.0f;
      in.f32(x);
      in.f32(y);
      in.f32(z);
      if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
        return fail(which + " (" + b.name + "): point " + std::to_string(i) + " is not finite");
      }
      b.points.emplace_back(x, y, z);
    }
    s.bodies.push_back(std::move(b));
  }
  if (in.left() != 0) return fail(std::to_string(in.left()) + " bytes after the last body");
  r.station = std::move(s);
  return r;
}

LoadedStation load_station(const std::string& path) {
  std::vector<std::uint8_t> bytes;
  if (std::string e = sealed::load(path, bytes); !e.empty()) {
    LoadedStation r;
    r.error = std::move(e);
    return r;
  }
  return parse_station(bytes, path);
}

std::string save_station(const StationFile& s, const std::string& path) { return sealed::save(path, serialize_station(s)); }

}  // namespace trailnav::perception::registration
