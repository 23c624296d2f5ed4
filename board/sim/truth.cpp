#include "truth.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>

#include "figure.hpp"
#include "png.hpp"

namespace trailnav::sim {

namespace {
// cos_incidence is the cosine to the face's normal: the sine to the face.
const double kSideSightingSine = std::sin(kSideSightingAngle * std::numbers::pi / 180.0);
}  // namespace

bool side_shown(const Hit& hit) noexcept {
  return hit.kind == HitKind::object && hit.side && hit.below_top >= kSideSightingDepth &&
         hit.cos_incidence >= kSideSightingSine;
}

namespace {

namespace fs = std::filesystem;

struct Image {
  int w = 0, h = 0;
  std::vector<std::uint8_t> rgb;
  void set(int x, int y, std::array<std::uint8_t, 3> c) {
    if (x < 0 || y < 0 || x >= w || y >= h) return;
    const auto i = (static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x)) * 3;
    rgb[i] = c[0];
    rgb[i + 1] = c[1];
    rgb[i + 2] = c[2];
  }
};

constexpr std::array<std::array<std::uint8_t, 3>, kTerrainClasses> kClassColour = {{
    {150, 150, 155},  // street
    {176, 128, 72},   // dirt
    {96, 170, 72},    // grass
    {34, 102, 44},    // vegetation
    {205, 195, 165},  // other
}};

Status write_raster(const std::string& path, const World& w, const std::vector<std::uint8_t>& data) {
  // North up: PNG row 0 is the world's northmost sample row.
  std::vector<std::uint8_t> flipped(data.size());
  const auto nx = static_cast<std::size_t>(w.width());
  const auto ny = static_cast<std::size_t>(w.height());
  for (std::size_t j = 0; j < ny; ++j) {
    std::copy_n(data.begin() + static_cast<std::ptrdiff_t>(j * nx), nx, flipped.begin() + static_cast<std::ptrdiff_t>((ny - 1 - j) * nx));
  }
  return cli::write_png(path, static_cast<std::uint32_t>(nx), static_cast<std::uint32_t>(ny), cli::PngColor::grey, flipped);
}

// Little-endian uint32 per pixel, row 0 at the south edge.
Status write_u32_raster(const std::string& path, const std::vector<std::uint32_t>& values) {
  std::vector<std::uint8_t> bytes(values.size() * 4);
  for (std::size_t i = 0; i < values.size(); ++i) {
    for (std::size_t b = 0; b < 4; ++b) bytes[i * 4 + b] = static_cast<std::uint8_t>(values[i] >> (8 * b));
  }
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f || std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size()) {
    if (f) std::fclose(f);
    return Status::error("cannot write " + path);
  }
  std::fclose(f);
  return Status::ok();
}

}  // namespace

Status write_truth(const std::string& dir, const Scenario& s, std::uint64_t seed, const World& world,
                   const RoadNetwork& roads, const Trajectory& traj, const GeoFrame& geo,
                   const Sightings& sightings) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status::error("cannot create " + dir + ": " + ec.message());

  // The scenario as used.
  if (std::FILE* f = std::fopen((dir + "/scenario.yaml").c_str(), "w")) {
    std::fprintf(f, "# trailnav sim: scenario %s from %s, seed %llu\n", s.name.c_str(), s.source.c_str(),
                 static_cast<unsigned long long>(seed));
    std::fputs(s.text.c_str(), f);
    std::fclose(f);
  } else {
    return Status::error("cannot write " + dir + "/scenario.yaml");
  }

  // Trajectory at 100 Hz.
  std::FILE* f = std::fopen((dir + "/trajectory.csv").c_str(), "w");
  if (!f) return Status::error("cannot write " + dir + "/trajectory.csv");
  std::fprintf(f, "time_s,utc_ns,x,y,z,roll,pitch,yaw,speed,yaw_rate,v_left,v_right,route_arc,lat,lon\n");
  for (std::size_t i = 0; i < traj.samples.size(); i += 2) {
    const PoseSample& p = traj.samples[i];
    double lat = 0, lon = 0;
    geo.to_latlon(p.p.x(), p.p.y(), lat, lon);
    std::fprintf(f, "%.3f,%lld,%.4f,%.4f,%.4f,%.6f,%.6f,%.6f,%.4f,%.5f,%.4f,%.4f,%.3f,%.9f,%.9f\n", p.t,
                 static_cast<long long>(s.start_utc_ns + std::llround(p.t * 1e9)), p.p.x(), p.p.y(), p.p.z(), p.roll,
                 p.pitch, p.yaw, p.v, p.yaw_rate, p.v_left, p.v_right, p.arc, lat, lon);
  }
  std::fclose(f);

  // Centrelines and junctions.
  f = std::fopen((dir + "/centrelines.csv").c_str(), "w");
  if (!f) return Status::error("cannot write " + dir + "/centrelines.csv");
  std::fprintf(f, "trail,arc,x,y,lat,lon\n");
  for (const TrailGeometry& t : roads.trails) {
    for (std::size_t i = 0; i < t.centre.points.size(); ++i) {
      double lat = 0, lon = 0;
      geo.to_latlon(t.centre.points[i].x(), t.centre.points[i].y(), lat, lon);
      std::fprintf(f, "%s,%.3f,%.4f,%.4f,%.9f,%.9f\n", t.spec->name.c_str(), t.centre.s[i], t.centre.points[i].x(),
                   t.centre.points[i].y(), lat, lon);
    }
  }
  std::fclose(f);
  f = std::fopen((dir + "/junctions.csv").c_str(), "w");
  if (!f) return Status::error("cannot write " + dir + "/junctions.csv");
  std::fprintf(f, "trail_a,trail_b,kind,x,y,osm_x,osm_y,arc_a,arc_b\n");
  for (const Junction& j : roads.junctions) {
    const char* kind = j.kind == JunctionKind::x ? "X" : j.kind == JunctionKind::t ? "T" : "L";
    std::fprintf(f, "%s,%s,%s,%.4f,%.4f,%.4f,%.4f,%.3f,%.3f\n", roads.trails[static_cast<std::size_t>(j.a)].spec->name.c_str(),
                 roads.trails[static_cast<std::size_t>(j.b)].spec->name.c_str(), kind, j.point.x(), j.point.y(),
                 j.mapped.x(), j.mapped.y(), j.arc_a, j.arc_b);
  }
  std::fclose(f);
  f = std::fopen((dir + "/route.csv").c_str(), "w");
  if (!f) return Status::error("cannot write " + dir + "/route.csv");
  std::fprintf(f, "arc,x,y\n");
  for (std::size_t i = 0; i < roads.route.points.size(); ++i) {
    std::fprintf(f, "%.3f,%.4f,%.4f\n", roads.route.s[i], roads.route.points[i].x(), roads.route.points[i].y());
  }
  std::fclose(f);

  // Rasters.
  if (Status st = write_raster(dir + "/terrain.png", world, world.terrain_raster()); !st) return st;
  if (Status st = write_raster(dir + "/obstacles.png", world, world.obstacle_raster()); !st) return st;
  const bool sighted = sightings.any.size() == world.obstacle_raster().size() &&
                       sightings.side_hit.size() == world.obstacle_raster().size() &&
                       sightings.side.size() == world.obstacle_raster().size();
  if (sighted) {
    if (Status st = write_u32_raster(dir + "/sightings.u32", sightings.any); !st) return st;
    if (Status st = write_u32_raster(dir + "/side_hits.u32", sightings.side_hit); !st) return st;
    if (Status st = write_u32_raster(dir + "/side_sightings.u32", sightings.side); !st) return st;
  }
  const bool returned = sightings.returns.size() == world.obstacle_raster().size();
  if (returned) {
    if (Status st = write_u32_raster(dir + "/returns.u32", sightings.returns); !st) return st;
  }
  f = std::fopen((dir + "/rasters.yaml").c_str(), "w");
  if (!f) return Status::error("cannot write " + dir + "/rasters.yaml");
  std::fprintf(f,
               "# Truth rasters of the simulated world (docs/simulator.md).\n"
               "frame: world  # x east, y north, metres from the origin, in UTM zone %d%s\n"
               "origin: {lat: %.9f, lon: %.9f}\n"
               "resolution: %.4f   # m per pixel\n"
               "width: %d\n"
               "height: %d\n"
               "south_west: [%.4f, %.4f]   # world x, y of the bottom-left pixel's centre\n"
               "rows: north_up   # PNG row 0 is the northmost\n"
               "terrain.png: {0: street, 1: dirt, 2: grass, 3: vegetation, 4: other}\n"
               "obstacles.png: {0: free, 1: obstacle, 2: negative obstacle, 3: vegetation}\n",
               geo.zone(), geo.north() ? "N" : "S", s.origin_lat, s.origin_lon, world.resolution(), world.width(),
               world.height(), world.x0(), world.y0());
  if (sighted) {
    std::fprintf(f,
                 "sightings.u32: {type: uint32 little-endian, rows: south_up, value: \"ms after the start + 1 of the first "
                 "lidar return from a solid obstacle in the pixel; 0: never\"}\n"
                 "side_hits.u32: {type: uint32 little-endian, rows: south_up, value: \"the same for returns from an "
                 "obstacle's side (a vertical face, not its top) within %.0f m of the sensor\"}\n"
                 "side_sightings.u32: {type: uint32 little-endian, rows: south_up, value: \"the same for the side returns "
                 "that show the face: at least %.2f m below the obstacle's top, meeting the face at %.0f degrees or "
                 "more\"}\n",
                 kSideSightingRange, kSideSightingDepth, kSideSightingAngle);
  }
  if (returned) {
    std::fprintf(f,
                 "returns.u32: {type: uint32 little-endian, rows: south_up, value: \"ms after the start + 1 of the first "
                 "lidar return of any kind (ground, obstacle, vegetation) in the pixel; 0: never\"}\n");
  }
  std::fclose(f);

  // Overview: terrain colours, obstacles, true trails, OSM ways, the driven path.
  const int scale = std::max(1, static_cast<int>(std::ceil(std::max(world.width(), world.height()) / 2400.0)));
  Image img;
  img.w = (world.width() + scale - 1) / scale;
  img.h = (world.height() + scale - 1) / scale;
  img.rgb.assign(static_cast<std::size_t>(img.w) * static_cast<std::size_t>(img.h) * 3, 0);
  const auto& cls = world.terrain_raster();
  const auto& obs = world.obstacle_raster();
  for (int y = 0; y < img.h; ++y) {
    for (int x = 0; x < img.w; ++x) {
      const int i = std::min(x * scale, world.width() - 1);
      const int j = std::min((img.h - 1 - y) * scale, world.height() - 1);
      const std::size_t idx = static_cast<std::size_t>(j) * static_cast<std::size_t>(world.width()) + static_cast<std::size_t>(i);
      std::array<std::uint8_t, 3> c = kClassColour[cls[idx]];
      if (obs[idx] == 1) c = {210, 30, 30};
      else if (obs[idx] == 2) c = {110, 20, 140};
      else if (obs[idx] == 3) c = {10, 64, 20};
      img.set(x, y, c);
    }
  }
  auto to_px = [&](const Vec2& p, int& x, int& y) {
    x = static_cast<int>(std::lround((p.x() - world.x0()) / world.resolution() / scale));
    y = img.h - 1 - static_cast<int>(std::lround((p.y() - world.y0()) / world.resolution() / scale));
  };
  auto line = [&](const Vec2& a, const Vec2& b, std::array<std::uint8_t, 3> c, int thick) {
    const double len = (b - a).norm() / world.resolution() / scale;
    const int n = std::max(1, static_cast<int>(std::ceil(len * 2)));
    for (int k = 0; k <= n; ++k) {
      int x = 0, y = 0;
      to_px(a + (b - a) * (static_cast<double>(k) / n), x, y);
      for (int dy = -thick / 2; dy <= thick / 2; ++dy) {
        for (int dx = -thick / 2; dx <= thick / 2; ++dx) img.set(x + dx, y + dy, c);
      }
    }
  };
  auto dot = [&](const Vec2& p, std::array<std::uint8_t, 3> c, int r) {
    int x = 0, y = 0;
    to_px(p, x, y);
    for (int dy = -r; dy <= r; ++dy) {
      for (int dx = -r; dx <= r; ++dx) {
        if (dx * dx + dy * dy <= r * r) img.set(x + dx, y + dy, c);
      }
    }
  };
  const int thick = std::max(1, 3 - scale);
  for (const OsmWay& way : roads.osm) {
    for (std::size_t i = 0; i + 1 < way.points.size(); ++i) line(way.points[i], way.points[i + 1], {230, 40, 220}, thick);
  }
  for (const TrailGeometry& t : roads.trails) {
    for (std::size_t i = 0; i + 1 < t.centre.points.size(); ++i) line(t.centre.points[i], t.centre.points[i + 1], {255, 255, 255}, 1);
  }
  for (std::size_t i = 0; i + 10 < traj.samples.size(); i += 10) {
    line(traj.samples[i].p.head<2>(), traj.samples[i + 10].p.head<2>(), {30, 80, 230}, 1);
  }
  for (const Junction& j : roads.junctions) {
    dot(j.point, {255, 220, 0}, 3);
    dot(j.mapped, {0, 220, 230}, 3);
  }
  const auto rgb = [](std::array<std::uint8_t, 3> c) { return cli::Rgb{c[0], c[1], c[2]}; };
  cli::MapFigure figure;
  figure.title = "simulated world: " + s.name;
  char text[160];
  std::snprintf(text, sizeof text, "%d x %d m, drawn at %.2f m per pixel; origin %.6f, %.6f (UTM zone %d%s)",
                static_cast<int>(std::lround(world.width() * world.resolution())),
                static_cast<int>(std::lround(world.height() * world.resolution())), world.resolution() * scale,
                s.origin_lat, s.origin_lon, geo.zone(), geo.north() ? "N" : "S");
  figure.notes = {text, "SIMULATED truth (docs/simulator.md)"};
  figure.legend = {{rgb(kClassColour[0]), "street"},
                   {rgb(kClassColour[1]), "dirt"},
                   {rgb(kClassColour[2]), "grass"},
                   {rgb(kClassColour[3]), "vegetation (ground)"},
                   {rgb(kClassColour[4]), "other ground"},
                   {{210, 30, 30}, "obstacle"},
                   {{110, 20, 140}, "negative obstacle"},
                   {{10, 64, 20}, "vegetation (obstacle)"},
                   {{230, 40, 220}, "OSM ways"},
                   {{255, 255, 255}, "true trail centres"},
                   {{30, 80, 230}, "driven path"},
                   {{255, 220, 0}, "junction, true"},
                   {{0, 220, 230}, "junction, as mapped"}};
  figure.metres_per_pixel = world.resolution() * scale;
  return cli::write_map_figure(dir + "/overview.png", img.rgb, img.w, img.h, figure);
}

}  // namespace trailnav::sim
