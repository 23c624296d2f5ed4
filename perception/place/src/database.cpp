#include "trailnav/perception/place/database.hpp"

#include <cmath>

#include "trailnav/runtime/le_bytes.hpp"
#include "trailnav/runtime/sealed_file.hpp"

namespace trailnav::perception::place {
namespace {

constexpr char kMagic[8] = {'T', 'N', 'P', 'L', 'A', 'C', 'E', '\0'};

}  // namespace

std::vector<std::uint8_t> serialize_place_database(const PlaceDatabase& db) {
  std::vector<std::uint8_t> out = sealed::begin(kMagic, kPlaceFileVersion);
  le::put_u16(out, static_cast<std::uint16_t>(db.width));
  le::put_u16(out, static_cast<std::uint16_t>(db.height));
  le::put_u16(out, static_cast<std::uint16_t>(db.hog.patch));
  le::put_u16(out, static_cast<std::uint16_t>(db.hog.cells));
  le::put_u16(out, static_cast<std::uint16_t>(db.hog.bins));
  le::put_f32(out, db.hog.clip);
  le::put_u32(out, static_cast<std::uint32_t>(db.length));
  le::put_u16(out, static_cast<std::uint16_t>(db.source.size()));
  out.insert(out.end(), db.source.begin(), db.source.end());
  le::put_u32(out, static_cast<std::uint32_t>(db.entries.size()));
  for (const PlaceEntry& e : db.entries) {
    le::put_u64(out, static_cast<std::uint64_t>(e.time_ns));
    le::put_f64(out, e.x);
    le::put_f64(out, e.y);
    le::put_f64(out, e.yaw);
    le::put_f64(out, e.lat);
    le::put_f64(out, e.lon);
    out.insert(out.end(), e.code.begin(), e.code.end());
  }
  const Whitening& w = db.whitening;
  le::put_u32(out, static_cast<std::uint32_t>(w.rank));
  if (w.rank > 0) {
    le::put_f32(out, w.epsilon_relative);
    le::put_f32(out, w.base);
    for (float v : w.mean) le::put_f32(out, v);
    for (float v : w.gains) le::put_f32(out, v);
    for (float v : w.directions) le::put_f32(out, v);
  }
  sealed::seal(out);
  return out;
}

LoadedPlaceDatabase parse_place_database(std::span<const std::uint8_t> bytes, std::string_view what) {
  LoadedPlaceDatabase r;
  const std::string w(what);
  auto fail = [&](const std::string& e) {
    r.error = w + ": " + e;
    return r;
  };
  const sealed::Opened opened = sealed::open(bytes, kMagic, "place database");
  if (!opened.problem.empty()) return fail(opened.problem);
  const std::uint32_t version = opened.version;
  if (version != 1 && version != kPlaceFileVersion)
    return fail("version " + std::to_string(version) + ", this trailnav reads version " + std::to_string(kPlaceFileVersion) +
                " (make the database again with trailnav place-map)");
  if (!opened.checksum_ok) return fail("the checksum does not match: the file is damaged or cut short");
  le::Reader in(opened.body);
  PlaceDatabase db;
  std::uint16_t width = 0, height = 0, patch = 0, cells = 0, bins = 0;
  float clip = 0.0f;
  std::uint32_t length = 0;
  if (!in.u16(width) || !in.u16(height) || !in.u16(patch) || !in.u16(cells) || !in.u16(bins) || !in.f32(clip) ||
      !in.u32(length))
    return fail("the descriptor's settings are cut short");
  db.width = width;
  db.height = height;
  db.hog = HogConfig{patch, cells, bins, clip};
  db.length = static_cast<int>(length);
  if (patch < 2 || cells < 1 || bins < 2 || patch % cells != 0 || !(clip > 0.0f) || width < patch || height < patch)
    return fail("descriptor settings that describe no image (" + std::to_string(width) + " x " + std::to_string(height) +
                " frames, patch " + std::to_string(patch) + ", cells " + std::to_string(cells) + ", bins " +
                std::to_string(bins) + ")");
  const std::size_t expected = static_cast<std::size_t>(width / patch) * static_cast<std::size_t>(height / patch) *
                               static_cast<std::size_t>(cells) * cells * bins;
  if (length != expected)
    return fail("a descriptor of " + std::to_string(length) + " values where these settings make " + std::to_string(expected));
  std::uint16_t source_length = 0;
  if (!in.u16(source_length) || source_length > kPlaceMaxSource || !in.bytes(source_length, db.source))
    return fail("the source's name is cut short or longer than 256 bytes");
  std::uint32_t n = 0;
  if (!in.u32(n) || n < 1 || n > kPlaceMaxImages) return fail("images: 1 to 1,000,000");
  const std::size_t per = 8 + 5 * 8 + length;
  if (in.left() / per < n) return fail(std::to_string(n) + " images announced, the file holds fewer");
  db.entries.reserve(n);
  for (std::uint32_t k = 0; k < n; ++k) {
    PlaceEntry e;
    std::uint64_t t = 0;
    in.u64(t);
    e.time_ns = static_cast<std::int64_t>(t);
    in.f64(e.x);
    in.f64(e.y);
    in.f64(e.yaw);
    in.f64(e.lat);
    in.f64(e.lon);
    if (!std::isfinite(e.x) || !std::isfinite(e.y) || !std::isfinite(e.yaw))
      return fail("image " + std::to_string(k) + ": a pose that is not finite");
    in.bytes(length, e.code);
    double norm = 0.0;
    for (std::uint8_t c : e.code) norm += static_cast<double>(c) * static_cast<double>(c);
    e.norm = static_cast<float>(std::sqrt(norm));
    db.entries.push_back(std::move(e));
  }
  if (version >= 2) {
    std::uint32_t rank = 0;
    if (!in.u32(rank)) return fail("the whitening's rank is cut short");
    if (rank > static_cast<std::uint32_t>(kPlaceMaxRank) || (rank > 0 && rank >= n))
      return fail("a whitening of rank " + std::to_string(rank) + " (at most 1,024 and fewer than the images)");
    if (rank > 0) {
      Whitening& wh = db.whitening;
      wh.rank = static_cast<int>(rank);
      const std::size_t floats = 2 + n + rank + static_cast<std::size_t>(n) * rank;
      if (in.left() / 4 < floats) return fail("the whitening is cut short");
      in.f32(wh.epsilon_relative);
      in.f32(wh.base);
      const auto take = [&](std::vector<float>& v, std::size_t count) {
        v.resize(count);
        bool finite = true;
        for (float& x : v) {
          in.f32(x);
          finite = finite && std::isfinite(x);
        }
        return finite;
      };
      if (!std::isfinite(wh.base) || !(wh.base > 0.0f) || !take(wh.mean, n) || !take(wh.gains, rank) ||
          !take(wh.directions, static_cast<std::size_t>(n) * rank))
        return fail("the whitening holds a value that is not a finite number");
    }
  }
  if (in.left() != 0) return fail(std::to_string(in.left()) + " bytes after the last image");
  r.database = std::move(db);
  return r;
}

LoadedPlaceDatabase load_place_database(const std::string& path) {
  std::vector<std::uint8_t> bytes;
  if (std::string e = sealed::load(path, bytes); !e.empty()) {
    LoadedPlaceDatabase r;
    r.error = std::move(e);
    return r;
  }
  return parse_place_database(bytes, path);
}

std::string save_place_database(const PlaceDatabase& db, const std::string& path) {
  return sealed::save(path, serialize_place_database(db));
}

}  // namespace trailnav::perception::place
