#include "place_map.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include "number_rows.hpp"
#include "sim_truth.hpp"
#include "trailnav/drivers/camera/frame.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/perception/place/online.hpp"
#include "trailnav/perception/place/similarity.hpp"

namespace trailnav::eval {

namespace place = perception::place;
namespace fs = std::filesystem;

namespace {

bool read_pose_csv(const std::string& path, std::vector<TruthPose>& out, std::string& error) {
  error = read_number_rows(path, 4, 6, "`time,x,y,yaw[,lat,lon]`", [&](int, std::span<const double> f) {
    for (double v : f)
      if (!std::isfinite(v)) return std::string("a value that is not a finite number");
    TruthPose p;
    p.utc_ns = static_cast<std::int64_t>(std::llround(f[0] * 1e9));
    p.x = f[1];
    p.y = f[2];
    p.yaw = f[3];
    p.lat = f.size() == 6 ? f[4] : std::numeric_limits<double>::quiet_NaN();
    p.lon = f.size() == 6 ? f[5] : std::numeric_limits<double>::quiet_NaN();
    if (f.size() == 5) return std::string("latitude without longitude");
    if (!out.empty() && p.utc_ns <= out.back().utc_ns) return std::string("times must increase");
    if (!out.empty()) p.arc = out.back().arc + std::hypot(p.x - out.back().x, p.y - out.back().y);
    out.push_back(p);
    return std::string();
  });
  if (!error.empty()) return false;
  if (out.size() < 2) {
    error = path + ": fewer than two poses";
    return false;
  }
  return true;
}

}  // namespace

PlaceMapReport make_place_map(const PlaceMapOptions& o) {
  PlaceMapReport r;
  // Poses.
  std::vector<TruthPose> poses;
  if (o.poses.empty()) {
    auto loaded = load_sim_truth((fs::path(o.recording) / "truth").string());
    if (!loaded.truth) {
      r.error = o.recording + " is not a simulated recording with a true trajectory (" + loaded.error +
                "): give the drive's poses with --poses CSV";
      return r;
    }
    poses = loaded.truth->trajectory;
    r.pose_source = "simulated truth (" + o.recording + "/truth/trajectory.csv)";
  } else {
    if (!read_pose_csv(o.poses, poses, r.error)) return r;
    r.pose_source = o.poses;
  }
  auto opened = recording::RecordingReader::open(o.recording);
  if (!opened.reader) {
    r.error = opened.error;
    return r;
  }
  recording::RecordingReader& reader = *opened.reader;
  int stream = -1;
  for (std::size_t i = 0; i < reader.streams().size(); ++i) {
    const recording::StreamInfo& s = reader.streams()[i];
    if (s.kind != recording::StreamKind::image || (!o.camera.empty() && s.name != o.camera)) continue;
    if (stream >= 0) {
      r.error = o.recording + " has several image streams: name one with --camera";
      return r;
    }
    stream = static_cast<int>(i);
  }
  if (stream < 0) {
    r.error = o.recording + (o.camera.empty() ? " has no image stream" : " has no image stream '" + o.camera + "'");
    return r;
  }
  place::PlaceDatabase& db = r.database;
  db.width = o.width;
  db.height = o.height;
  db.source = fs::path(o.recording).filename().string().substr(0, place::kPlaceMaxSource);
  place::Hog hog(o.hog, o.width, o.height);
  db.hog = hog.config();
  db.length = hog.length();
  std::vector<float> f(static_cast<std::size_t>(hog.length()));
  std::unique_ptr<drivers::camera::FrameConverter> converter;
  int conv_w = 0, conv_h = 0;
  double last_arc = -1e300;
  double last_x = 0, last_y = 0;
  bool have_last = false;
  while (auto e = reader.next()) {
    if (e->stream != stream) continue;
    ++r.frames;
    if (o.progress && reader.size() > 0) o.progress(static_cast<double>(reader.position()) / static_cast<double>(reader.size()));
    TruthAt at;
    if (!truth_at(poses, e->time_ns, at)) {
      ++r.without_pose;
      continue;
    }
    if (o.every_m > 0.0 && at.arc - last_arc < o.every_m) {
      ++r.too_close;
      continue;
    }
    if (!converter || conv_w != e->image_width || conv_h != e->image_height) {
      if (e->image_width < o.width || e->image_height < o.height) {
        r.error = o.recording + ": a frame of " + std::to_string(e->image_width) + " x " + std::to_string(e->image_height) +
                  " pixels is smaller than the descriptor's " + std::to_string(o.width) + " x " + std::to_string(o.height);
        return r;
      }
      converter = std::make_unique<drivers::camera::FrameConverter>(drivers::camera::PixelFormat::grey, e->image_width,
                                                                    e->image_height, o.width, o.height);
      conv_w = e->image_width;
      conv_h = e->image_height;
    }
    converter->convert(e->payload, e->image_width);
    hog.compute(converter->grey(), o.width, f);
    place::PlaceEntry entry;
    entry.time_ns = e->time_ns;
    entry.x = at.x;
    entry.y = at.y;
    entry.yaw = at.yaw;
    entry.lat = at.lat;
    entry.lon = at.lon;
    entry.code.resize(f.size());
    entry.norm = place::encode_descriptor(f, entry.code);
    if (have_last) r.path_m += std::hypot(at.x - last_x, at.y - last_y);
    last_x = at.x;
    last_y = at.y;
    have_last = true;
    last_arc = at.arc;
    db.entries.push_back(std::move(entry));
  }
  if (db.entries.empty()) {
    r.error = o.recording + ": no frame of the image stream lies within the poses' time span";
    return r;
  }
  if (db.entries.size() > place::kPlaceMaxImages) {
    r.error = std::to_string(db.entries.size()) + " images: a database holds at most 1,000,000 (raise --every)";
    return r;
  }
  if (o.zca_rank > 0 && db.entries.size() > 2) {
    std::vector<std::uint8_t> codes;
    std::vector<float> norms;
    codes.reserve(db.entries.size() * static_cast<std::size_t>(db.length));
    for (const place::PlaceEntry& e : db.entries) {
      codes.insert(codes.end(), e.code.begin(), e.code.end());
      norms.push_back(e.norm);
    }
    db.whitening = place::learn_whitening(codes, norms, db.length, std::min(o.zca_rank, place::kPlaceMaxRank), o.zca_epsilon);
  }
  return r;
}

}  // namespace trailnav::eval
