#include "trailnav/perception/registration/station_file.hpp"

#include <zlib.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>

#include "trailnav/runtime/atomic_file.hpp"

namespace trailnav::perception::registration {

namespace {

constexpr char kMagic[8] = {'T', 'N', 'S', 'T', 'A', 'T', 'N', '\0'};

template <typename T>
void put(std::vector<std::uint8_t>& out, T v) {
  std::uint8_t b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));  // little-endian hosts only (x86-64, arm64)
  out.insert(out.end(), b, b + sizeof(T));
}

void put_string(std::vector<std::uint8_t>& out, const std::string& s) {
  put<std::uint16_t>(out, static_cast<std::uint16_t>(s.size()));
  out.insert(out.end(), s.begin(), s.end());
}

std::uint32_t crc_of(std::span<const std::uint8_t> bytes) {
  return static_cast<std::uint32_t>(crc32(0L, bytes.data(), static_cast<uInt>(bytes.size())));
}

class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> b) : bytes_(b) {}
  template <typename T>
  bool get(T& v) {
    if (bytes_.size() - at_ < sizeof(T)) return false;
    std::memcpy(&v, bytes_.data() + at_, sizeof(T));
    at_ += sizeof(T);
    return true;
  }
  bool get_string(std::string& s, std::size_t max) {
    std::uint16_t n = 0;
    if (!get(n) || n > max || bytes_.size() - at_ < n) return false;
    s.assign(reinterpret_cast<const char*>(bytes_.data() + at_), n);
    at_ += n;
    return true;
  }
  std::size_t at() const noexcept { return at_; }
  std::size_t left() const noexcept { return bytes_.size() - at_; }

 private:
  std::span<const std::uint8_t> bytes_;
  std::size_t at_ = 0;
};

}  // namespace

std::vector<std::uint8_t> serialize_station(const StationFile& s) {
  std::vector<std::uint8_t> out(kMagic, kMagic + sizeof kMagic);
  put<std::uint32_t>(out, kStationFileVersion);
  put_string(out, s.name);
  put<std::uint32_t>(out, static_cast<std::uint32_t>(s.bodies.size()));
  for (const StationBodyFile& b : s.bodies) {
    put_string(out, b.name);
    put<std::uint32_t>(out, static_cast<std::uint32_t>(b.polygon.size()));
    for (const Eigen::Vector2d& c : b.polygon) {
      put<double>(out, c.x());
      put<double>(out, c.y());
    }
    put<std::uint32_t>(out, static_cast<std::uint32_t>(b.points.size()));
    for (const Point& p : b.points) {
      put<float>(out, p.x());
      put<float>(out, p.y());
      put<float>(out, p.z());
    }
  }
  put<std::uint32_t>(out, crc_of(out));
  return out;
}

LoadedStation parse_station(std::span<const std::uint8_t> bytes, std::string_view what) {
  LoadedStation r;
  const std::string w(what);
  auto fail = [&](const std::string& e) {
    r.error = w + ": " + e;
    return r;
  };
  if (bytes.size() < sizeof kMagic + 8 || std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0) {
    return fail("not a trailnav station file (it does not begin with TNSTATN)");
  }
  const std::span<const std::uint8_t> body = bytes.first(bytes.size() - 4);
  std::uint32_t stored = 0;
  std::memcpy(&stored, bytes.data() + bytes.size() - 4, 4);
  Reader in(body.subspan(sizeof kMagic));
  std::uint32_t version = 0;
  in.get(version);
  if (version != kStationFileVersion) {
    return fail("version " + std::to_string(version) + ", this trailnav reads version " +
                std::to_string(kStationFileVersion) + " (teach the station again)");
  }
  if (crc_of(body) != stored) return fail("the checksum does not match: the file is damaged or cut short");
  StationFile s;
  if (!in.get_string(s.name, kStationMaxName)) return fail("the station's name is cut short or longer than 64 bytes");
  std::uint32_t nb = 0;
  if (!in.get(nb) || nb < 1 || nb > kStationMaxBodies) return fail("bodies: 1 to 64 (the surroundings and the objects)");
  for (std::uint32_t k = 0; k < nb; ++k) {
    StationBodyFile b;
    const std::string which = "body " + std::to_string(k);
    if (!in.get_string(b.name, kStationMaxName) || b.name.empty()) return fail(which + ": a name of 1 to 64 bytes");
    std::uint32_t corners = 0;
    if (!in.get(corners)) return fail(which + " (" + b.name + "): cut short");
    if (k == 0 ? corners != 0 : (corners < 3 || corners > kStationMaxCorners)) {
      return fail(which + " (" + b.name + "): " + std::to_string(corners) + " polygon corners; the surroundings have none, "
                  "an object 3 to 1024");
    }
    if (in.left() / 16 < corners) return fail(which + " (" + b.name + "): its polygon is cut short");
    for (std::uint32_t c = 0; c < corners; ++c) {
      double x = 0.0, y = 0.0;
      in.get(x);
      in.get(y);
      if (!std::isfinite(x) || !std::isfinite(y)) return fail(which + " (" + b.name + "): a polygon corner is not finite");
      b.polygon.emplace_back(x, y);
    }
    std::uint32_t n = 0;
    if (!in.get(n) || n > kStationMaxPoints) return fail(which + " (" + b.name + "): at most 4,194,304 points");
    if (in.left() / 12 < n) return fail(which + " (" + b.name + "): its points are cut short");
    b.points.reserve(n);
    for (std::uint32_t i = 0; i < n; ++i) {
      float x = 0.0f, y = 0.0f, z = 0.0f;
      in.get(x);
      in.get(y);
      in.get(z);
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
  std::ifstream f(path, std::ios::binary);
  if (!f) {
    LoadedStation r;
    r.error = path + ": cannot open (" + std::strerror(errno) + ")";
    return r;
  }
  const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  return parse_station(bytes, path);
}

std::string save_station(const StationFile& s, const std::string& path) {
  const AtomicFile file(path);
  if (const int e = file.write(serialize_station(s)); e != 0) return path + ": cannot write (" + std::strerror(e) + ")";
  return "";
}

}  // namespace trailnav::perception::registration
