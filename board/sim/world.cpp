#include "world.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "random.hpp"

namespace trailnav::sim {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kRobotHeight = 1.5;   // m: obstacles matter up to here
constexpr double kStepTruth = 0.1;     // m: a height jump this big between neighbours is an obstacle
constexpr double kDitchTruth = 0.15;   // m: deeper is a negative obstacle
constexpr double kCanopyDensity = 3.0; // hits per metre of leaves

bool inside_polygon(const std::vector<Vec2>& poly, double x, double y) {
  bool in = false;
  for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const Vec2& a = poly[i];
    const Vec2& b = poly[j];
    if ((a.y() > y) != (b.y() > y) && x < (b.x() - a.x()) * (y - a.y()) / (b.y() - a.y()) + a.x()) in = !in;
  }
  return in;
}

double segment_distance(const Vec2& p, const Vec2& a, const Vec2& b) {
  const Vec2 d = b - a;
  const double l2 = d.squaredNorm();
  const double u = l2 > 0 ? std::clamp((p - a).dot(d) / l2, 0.0, 1.0) : 0.0;
  return (p - (a + d * u)).norm();
}

// Walks the cells of a square grid that a ray crosses, in order.
struct Dda {
  int i = 0;
  int j = 0;
  int si = 0;
  int sj = 0;
  double next_i = kInf;
  double next_j = kInf;
  double di = kInf;
  double dj = kInf;

  // (u, v): ray position in grid units at parameter t; (du, dv): grid units per unit t.
  void start(double u, double v, double du, double dv, double t, double cell, int ni, int nj) {
    axis(u, du, t, cell, ni, i, si, next_i, di);
    axis(v, dv, t, cell, nj, j, sj, next_j, dj);
  }
  // One axis: the cell index, its step, and where the ray leaves the cell.
  static void axis(double u, double du, double t, double cell, int n, int& index, int& step, double& next, double& delta) {
    index = std::clamp(static_cast<int>(std::floor(u / cell)), 0, n - 1);
    if (du > 0) {
      step = 1;
      delta = cell / du;
      next = t + ((index + 1) * cell - u) / du;
    } else if (du < 0) {
      step = -1;
      delta = -cell / du;
      next = t + (index * cell - u) / du;
    } else {
      step = 0;
      next = kInf;
    }
  }
  double exit() const { return std::min(next_i, next_j); }
  void step() {
    if (next_i < next_j) {
      i += si;
      next_i += di;
    } else {
      j += sj;
      next_j += dj;
    }
  }
};

}  // namespace

struct World::Primitive {
  enum class Shape : std::uint8_t { box, cylinder, ellipsoid } shape = Shape::box;
  Vec3 c{0, 0, 0};     // box/cylinder: footprint centre and z0 in z; ellipsoid: centre
  Vec3 half{0, 0, 0};  // box half extents (z: half height); ellipsoid radii
  double cos_yaw = 1.0;
  double sin_yaw = 0.0;
  double radius = 0.0;  // cylinder
  double z0 = 0.0;
  double z1 = 0.0;
  double remission = 40.0;
  TerrainClass terrain = TerrainClass::other;
  Vec2 lo{0, 0};
  Vec2 hi{0, 0};
};

World::~World() = default;

std::unique_ptr<World> World::build(const Scenario& s, const RoadNetwork& roads, std::uint64_t seed) {
  std::unique_ptr<World> w(new World());
  const WorldSpec& ws = s.world;
  w->seed_ = seed;
  w->materials_ = s.materials;
  w->res_ = ws.resolution;
  w->inv_res_ = 1.0 / ws.resolution;
  w->x0_ = ws.xmin;
  w->y0_ = ws.ymin;
  w->nx_ = static_cast<int>(std::floor((ws.xmax - ws.xmin) / ws.resolution)) + 1;
  w->ny_ = static_cast<int>(std::floor((ws.ymax - ws.ymin) / ws.resolution)) + 1;
  const auto n = static_cast<std::size_t>(w->nx_) * static_cast<std::size_t>(w->ny_);
  w->h_.assign(n, 0.0f);
  w->med_.assign(n, 0.0f);
  w->dens_.assign(n, 0.0f);
  w->refl_.assign(n, 0);
  w->cls_.assign(n, static_cast<std::uint8_t>(ws.background));
  w->ditch_.assign(n, 0.0f);

  // Which medium each sample grows: -1 none, 0 background, 1 + region index.
  std::vector<std::int16_t> medium_of(n, ws.background_medium.present() ? 0 : -1);
  for (std::size_t r = 0; r < s.regions.size(); ++r) {
    const Region& region = s.regions[r];
    Vec2 lo = region.polygon[0], hi = region.polygon[0];
    for (const Vec2& p : region.polygon) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    const auto [i0, i1, j0, j1] = w->samples_within(lo.x(), lo.y(), hi.x(), hi.y());
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        if (!inside_polygon(region.polygon, w->x0_ + i * w->res_, w->y0_ + j * w->res_)) continue;
        w->cls_[w->index(i, j)] = static_cast<std::uint8_t>(region.terrain);
        medium_of[w->index(i, j)] = region.medium.present() ? static_cast<std::int16_t>(r + 1) : -1;
      }
    }
  }

  // Trails: the nearest trail within its half width owns a sample.
  std::vector<float> edge(n, std::numeric_limits<float>::max());  // distance to the nearest trail edge, <0 inside
  std::vector<std::int16_t> trail_of(n, -1);
  for (std::size_t t = 0; t < roads.trails.size(); ++t) {
    const TrailGeometry& tg = roads.trails[t];
    const double half = tg.spec->width / 2.0;
    const auto& pts = tg.centre.points;
    for (std::size_t k = 0; k + 1 < pts.size(); ++k) {
      const Vec2 lo = pts[k].cwiseMin(pts[k + 1]) - Vec2(half + 0.5, half + 0.5);
      const Vec2 hi = pts[k].cwiseMax(pts[k + 1]) + Vec2(half + 0.5, half + 0.5);
      const auto [i0, i1, j0, j1] = w->samples_within(lo.x(), lo.y(), hi.x(), hi.y());
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) {
          const Vec2 p(w->x0_ + i * w->res_, w->y0_ + j * w->res_);
          const auto e = static_cast<float>(segment_distance(p, pts[k], pts[k + 1]) - half);
          const std::size_t idx = w->index(i, j);
          if (e < edge[idx]) {
            edge[idx] = e;
            trail_of[idx] = static_cast<std::int16_t>(t);
          }
        }
      }
    }
  }

  const std::uint64_t k_hill = hash(seed, 0x4111);
  const std::uint64_t k_rough = hash(seed, 0x2002);
  const std::uint64_t k_med_h = hash(seed, 0x3003);
  const std::uint64_t k_med_c = hash(seed, 0x3004);
  const std::uint64_t k_refl = hash(seed, 0x5005);
  const std::uint64_t k_refl_s = hash(seed, 0x5006);
  const std::uint64_t k_dirt = hash(seed, 0x5007);
  for (int j = 0; j < w->ny_; ++j) {
    for (int i = 0; i < w->nx_; ++i) {
      const std::size_t idx = w->index(i, j);
      const double x = w->x0_ + i * w->res_;
      const double y = w->y0_ + j * w->res_;
      double h = ws.slope.x() * x + ws.slope.y() * y;
      if (ws.hill_amplitude > 0) h += ws.hill_amplitude * fractal_noise(k_hill, x, y, ws.hill_wavelength);
      const bool on_trail = trail_of[idx] >= 0 && edge[idx] <= 0.0f;
      if (on_trail) {
        const Trail& t = *roads.trails[static_cast<std::size_t>(trail_of[idx])].spec;
        w->cls_[idx] = static_cast<std::uint8_t>(t.terrain);
        h -= t.curb;
        medium_of[idx] = t.medium.present() ? static_cast<std::int16_t>(-2 - trail_of[idx]) : -1;
      }
      const auto cls = static_cast<TerrainClass>(w->cls_[idx]);
      const Material& mat = s.materials[w->cls_[idx]];
      h += mat.roughness * (fractal_noise(k_rough, x, y, 0.9) + 0.4 * gaussian(hash(k_rough, idx)));
      w->h_[idx] = static_cast<float>(h);

      if (medium_of[idx] >= 0 || medium_of[idx] <= -2) {
        const Medium& m = medium_of[idx] <= -2 ? roads.trails[static_cast<std::size_t>(-2 - medium_of[idx])].spec->medium
                          : medium_of[idx] == 0 ? ws.background_medium
                                                : s.regions[static_cast<std::size_t>(medium_of[idx] - 1)].medium;
        const double coverage = 0.5 + 0.5 * value_noise(k_med_c, x, y, m.clump_size * 1.3);
        if (coverage < m.cover) {
          const double f = 0.5 + 0.5 * fractal_noise(k_med_h, x, y, m.clump_size);
          w->med_[idx] = static_cast<float>(m.height_min + (m.height_max - m.height_min) * std::clamp(f, 0.0, 1.0));
          w->dens_[idx] = static_cast<float>(m.density);
        }
      }

      // Remission: the class's distribution, spatially correlated, with
      // dirt patches on streets.
      const Material* rm = &mat;
      if (cls == TerrainClass::street && ws.street_dirt > 0 &&
          0.5 + 0.5 * value_noise(k_dirt, x, y, 3.0) > 1.0 - ws.street_dirt) {
        rm = &s.materials[static_cast<std::size_t>(TerrainClass::dirt)];
      }
      const double r = rm->remission_mean +
                       rm->remission_std * (0.6 * value_noise(k_refl_s, x, y, 1.5) * 1.6 + 0.6 * gaussian(hash(k_refl, idx)));
      w->refl_[idx] = static_cast<std::uint8_t>(std::clamp(std::lround(r), 0L, 255L));
    }
  }

  // Bushes and ditches shape the field.
  for (const Obstacle& ob : s.obstacles) {
    if (ob.type == ObstacleType::bush) {
      const auto [i0, i1, j0, j1] = w->samples_within(ob.center.x() - ob.radius, ob.center.y() - ob.radius,
                                                       ob.center.x() + ob.radius, ob.center.y() + ob.radius);
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) {
          const Vec2 p(w->x0_ + i * w->res_, w->y0_ + j * w->res_);
          const double d = (p - ob.center).norm() / ob.radius;
          if (d >= 1.0) continue;
          const std::size_t idx = w->index(i, j);
          const double top = ob.height * std::sqrt(1.0 - d * d) * (0.85 + 0.15 * value_noise(k_med_h, p.x(), p.y(), 0.4));
          if (top > w->med_[idx]) {
            w->med_[idx] = static_cast<float>(top);
            w->dens_[idx] = 10.0f;
          }
          w->cls_[idx] = static_cast<std::uint8_t>(TerrainClass::vegetation);
        }
      }
    } else if (ob.type == ObstacleType::ditch) {
      const double half = ob.width / 2.0;
      for (std::size_t k = 0; k + 1 < ob.points.size(); ++k) {
        const Vec2 lo = ob.points[k].cwiseMin(ob.points[k + 1]) - Vec2(half, half);
        const Vec2 hi = ob.points[k].cwiseMax(ob.points[k + 1]) + Vec2(half, half);
        const auto [i0, i1, j0, j1] = w->samples_within(lo.x(), lo.y(), hi.x(), hi.y());
        for (int j = j0; j <= j1; ++j) {
          for (int i = i0; i <= i1; ++i) {
            const Vec2 p(w->x0_ + i * w->res_, w->y0_ + j * w->res_);
            const double d = segment_distance(p, ob.points[k], ob.points[k + 1]) / half;
            if (d >= 1.0) continue;
            const std::size_t idx = w->index(i, j);
            // Steep-sided U profile.
            const double depth = ob.depth * std::min(1.0, 2.5 * (1.0 - d));
            if (depth > w->ditch_[idx]) {
              w->h_[idx] -= static_cast<float>(depth - w->ditch_[idx]);
              w->ditch_[idx] = static_cast<float>(depth);
            }
          }
        }
      }
    }
  }

  w->build_primitives(s);
  w->build_blocks();
  w->build_truth();
  return w;
}

void World::build_primitives(const Scenario& s) {
  for (const Obstacle& ob : s.obstacles) {
    Primitive p;
    p.remission = ob.remission;
    switch (ob.type) {
      case ObstacleType::box:
      case ObstacleType::wall: {
        Vec2 c = ob.center;
        double len = ob.size.x(), wid = ob.size.y(), hgt = ob.size.z(), yaw = ob.yaw;
        if (ob.type == ObstacleType::wall) {
          c = (ob.points[0] + ob.points[1]) / 2.0;
          const Vec2 d = ob.points[1] - ob.points[0];
          len = d.norm();
          wid = ob.thickness;
          hgt = ob.height;
          yaw = std::atan2(d.y(), d.x());
        }
        p.shape = Primitive::Shape::box;
        p.cos_yaw = std::cos(yaw);
        p.sin_yaw = std::sin(yaw);
        p.half = {len / 2, wid / 2, hgt / 2};
        // Standing on the lowest ground under its corners.
        double base = kInf;
        for (int a = -1; a <= 1; a += 2) {
          for (int b = -1; b <= 1; b += 2) {
            const Vec2 q = c + Vec2(p.cos_yaw * a * p.half.x() - p.sin_yaw * b * p.half.y(),
                                    p.sin_yaw * a * p.half.x() + p.cos_yaw * b * p.half.y());
            base = std::min(base, ground(q.x(), q.y()));
          }
        }
        base = std::min(base, ground(c.x(), c.y()));
        p.c = {c.x(), c.y(), base};
        p.z0 = base;
        p.z1 = base + hgt;
        const double r = std::hypot(p.half.x(), p.half.y());
        p.lo = c - Vec2(r, r);
        p.hi = c + Vec2(r, r);
        primitives_.push_back(p);
        break;
      }
      case ObstacleType::pole:
      case ObstacleType::tree: {
        const double base = ground(ob.center.x(), ob.center.y()) - 0.05;
        p.shape = Primitive::Shape::cylinder;
        p.c = {ob.center.x(), ob.center.y(), base};
        p.radius = ob.radius;
        p.z0 = base;
        p.z1 = base + 0.05 + (ob.type == ObstacleType::tree ? ob.height - 0.3 * (ob.height - ob.canopy_base) : ob.height);
        p.lo = ob.center - Vec2(ob.radius, ob.radius);
        p.hi = ob.center + Vec2(ob.radius, ob.radius);
        p.terrain = TerrainClass::other;
        primitives_.push_back(p);
        if (ob.type == ObstacleType::tree && ob.canopy_radius > 0) {
          Primitive c;
          c.shape = Primitive::Shape::ellipsoid;
          const double rz = (ob.height - ob.canopy_base) / 2.0;
          c.c = {ob.center.x(), ob.center.y(), base + ob.canopy_base + rz};
          c.half = {ob.canopy_radius, ob.canopy_radius, rz};
          c.z0 = c.c.z() - rz;
          c.z1 = c.c.z() + rz;
          c.remission = ob.remission;
          c.terrain = TerrainClass::vegetation;
          c.lo = ob.center - Vec2(ob.canopy_radius, ob.canopy_radius);
          c.hi = ob.center + Vec2(ob.canopy_radius, ob.canopy_radius);
          primitives_.push_back(c);
        }
        break;
      }
      case ObstacleType::bush:
      case ObstacleType::ditch: break;  // part of the height field
    }
  }
}

void World::build_blocks() {
  bx_ = (nx_ - 1 + kBlock - 1) / kBlock;
  by_ = (ny_ - 1 + kBlock - 1) / kBlock;
  bx_ = std::max(bx_, 1);
  by_ = std::max(by_, 1);
  block_max_.assign(static_cast<std::size_t>(bx_) * static_cast<std::size_t>(by_), -std::numeric_limits<float>::max());
  z_top_ = -kInf;
  for (int j = 0; j < ny_; ++j) {
    for (int i = 0; i < nx_; ++i) {
      const float top = h_[index(i, j)] + med_[index(i, j)];
      z_top_ = std::max(z_top_, static_cast<double>(top));
      // A sample is a corner of the quads of up to four blocks.
      for (int bj = std::max(0, (j - 1) / kBlock); bj <= std::min(by_ - 1, j / kBlock); ++bj) {
        for (int bi = std::max(0, (i - 1) / kBlock); bi <= std::min(bx_ - 1, i / kBlock); ++bi) {
          float& m = block_max_[static_cast<std::size_t>(bj) * static_cast<std::size_t>(bx_) + static_cast<std::size_t>(bi)];
          m = std::max(m, top);
        }
      }
    }
  }
  std::vector<std::vector<std::uint32_t>> lists(block_max_.size());
  for (std::size_t p = 0; p < primitives_.size(); ++p) {
    const Primitive& pr = primitives_[p];
    z_top_ = std::max(z_top_, pr.z1);
    const double span = res_ * kBlock;
    const int i0 = std::clamp(static_cast<int>(std::floor((pr.lo.x() - x0_) / span)), 0, bx_ - 1);
    const int i1 = std::clamp(static_cast<int>(std::floor((pr.hi.x() - x0_) / span)), 0, bx_ - 1);
    const int j0 = std::clamp(static_cast<int>(std::floor((pr.lo.y() - y0_) / span)), 0, by_ - 1);
    const int j1 = std::clamp(static_cast<int>(std::floor((pr.hi.y() - y0_) / span)), 0, by_ - 1);
    for (int bj = j0; bj <= j1; ++bj) {
      for (int bi = i0; bi <= i1; ++bi) {
        const std::size_t b = static_cast<std::size_t>(bj) * static_cast<std::size_t>(bx_) + static_cast<std::size_t>(bi);
        lists[b].push_back(static_cast<std::uint32_t>(p));
        block_max_[b] = std::max(block_max_[b], static_cast<float>(pr.z1));
      }
    }
  }
  block_first_.assign(lists.size() + 1, 0);
  for (std::size_t b = 0; b < lists.size(); ++b) {
    block_first_[b + 1] = block_first_[b] + static_cast<std::uint32_t>(lists[b].size());
    block_items_.insert(block_items_.end(), lists[b].begin(), lists[b].end());
  }
}

void World::build_truth() {
  truth_.assign(h_.size(), static_cast<std::uint8_t>(ObstacleTruth::free));
  auto mark = [&](std::size_t idx, ObstacleTruth code) {
    if (truth_rank(static_cast<std::uint8_t>(code)) > truth_rank(truth_[idx])) truth_[idx] = static_cast<std::uint8_t>(code);
  };
  for (int j = 0; j < ny_; ++j) {
    for (int i = 0; i < nx_; ++i) {
      const std::size_t idx = index(i, j);
      if (ditch_[idx] >= kDitchTruth) mark(idx, ObstacleTruth::negative);
      // Tall grass is traversable; bushes and undergrowth are not.
      if (med_[idx] >= 0.5f && cls_[idx] == static_cast<std::uint8_t>(TerrainClass::vegetation)) {
        mark(idx, ObstacleTruth::vegetation);
      }
      if (i + 1 < nx_ && std::abs(h_[index(i + 1, j)] - h_[idx]) >= kStepTruth && ditch_[idx] == 0.0f &&
          ditch_[index(i + 1, j)] == 0.0f) {
        mark(idx, ObstacleTruth::obstacle);
        mark(index(i + 1, j), ObstacleTruth::obstacle);
      }
      if (j + 1 < ny_ && std::abs(h_[index(i, j + 1)] - h_[idx]) >= kStepTruth && ditch_[idx] == 0.0f &&
          ditch_[index(i, j + 1)] == 0.0f) {
        mark(idx, ObstacleTruth::obstacle);
        mark(index(i, j + 1), ObstacleTruth::obstacle);
      }
    }
  }
  for (const Primitive& p : primitives_) {
    const auto [i0, i1, j0, j1] = samples_within(p.lo.x(), p.lo.y(), p.hi.x(), p.hi.y());
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        const double x = x0_ + i * res_;
        const double y = y0_ + j * res_;
        const double g = h_[index(i, j)];
        // Does the primitive fill any height the robot occupies above this
        // sample? Cells count when the shape covers any part of them.
        const double m = res_ * 0.5;
        bool covers = false;
        if (p.shape == Primitive::Shape::box) {
          const double dx = x - p.c.x();
          const double dy = y - p.c.y();
          const double lx = std::abs(p.cos_yaw * dx + p.sin_yaw * dy);
          const double ly = std::abs(-p.sin_yaw * dx + p.cos_yaw * dy);
          covers = lx <= p.half.x() + m && ly <= p.half.y() + m;
        } else if (p.shape == Primitive::Shape::cylinder) {
          covers = std::hypot(x - p.c.x(), y - p.c.y()) <= p.radius + m;
        } else {
          const double d = std::hypot(x - p.c.x(), y - p.c.y()) / p.half.x();
          covers = d < 1.0;
        }
        if (!covers || p.z1 < g + 0.1 || p.z0 > g + kRobotHeight) continue;
        mark(index(i, j), p.shape == Primitive::Shape::ellipsoid ? ObstacleTruth::vegetation : ObstacleTruth::obstacle);
      }
    }
  }
}

World::SampleRange World::samples_within(double xlo, double ylo, double xhi, double yhi) const noexcept {
  return {std::max(0, static_cast<int>(std::floor((xlo - x0_) * inv_res_))),
          std::min(nx_ - 1, static_cast<int>(std::ceil((xhi - x0_) * inv_res_))),
          std::max(0, static_cast<int>(std::floor((ylo - y0_) * inv_res_))),
          std::min(ny_ - 1, static_cast<int>(std::ceil((yhi - y0_) * inv_res_)))};
}

double World::ground(double x, double y) const noexcept {
  const double u = std::clamp((x - x0_) * inv_res_, 0.0, static_cast<double>(nx_ - 1));
  const double v = std::clamp((y - y0_) * inv_res_, 0.0, static_cast<double>(ny_ - 1));
  const int i = std::min(static_cast<int>(u), std::max(nx_ - 2, 0));
  const int j = std::min(static_cast<int>(v), std::max(ny_ - 2, 0));
  const double f = u - i;
  const double g = v - j;
  const int i1 = std::min(i + 1, nx_ - 1);
  const int j1 = std::min(j + 1, ny_ - 1);
  return (h_[index(i, j)] * (1 - f) + h_[index(i1, j)] * f) * (1 - g) + (h_[index(i, j1)] * (1 - f) + h_[index(i1, j1)] * f) * g;
}

TerrainClass World::terrain(double x, double y) const noexcept {
  const int i = std::clamp(static_cast<int>(std::lround((x - x0_) * inv_res_)), 0, nx_ - 1);
  const int j = std::clamp(static_cast<int>(std::lround((y - y0_) * inv_res_)), 0, ny_ - 1);
  return static_cast<TerrainClass>(cls_[index(i, j)]);
}

Vec3 World::normal(double x, double y) const noexcept {
  const double e = res_;
  const double dx = (ground(x + e, y) - ground(x - e, y)) / (2 * e);
  const double dy = (ground(x, y + e) - ground(x, y - e)) / (2 * e);
  return Vec3(-dx, -dy, 1.0).normalized();
}

bool World::intersect(const Primitive& p, const Vec3& o, const Vec3& d, double t_lo, double t_hi, std::uint64_t ray_key,
                      Hit& hit) const noexcept {
  switch (p.shape) {
    case Primitive::Shape::box: {
      const double ox = o.x() - p.c.x();
      const double oy = o.y() - p.c.y();
      const double lox = p.cos_yaw * ox + p.sin_yaw * oy;
      const double loy = -p.sin_yaw * ox + p.cos_yaw * oy;
      const double ldx = p.cos_yaw * d.x() + p.sin_yaw * d.y();
      const double ldy = -p.sin_yaw * d.x() + p.cos_yaw * d.y();
      const double lo_[3] = {lox, loy, o.z() - (p.z0 + p.z1) / 2};
      const double ld[3] = {ldx, ldy, d.z()};
      const double half[3] = {p.half.x(), p.half.y(), (p.z1 - p.z0) / 2};
      double t0 = t_lo, t1 = t_hi;
      int axis = -1;
      for (int a = 0; a < 3; ++a) {
        if (std::abs(ld[a]) < 1e-12) {
          if (std::abs(lo_[a]) > half[a]) return false;
          continue;
        }
        double ta = (-half[a] - lo_[a]) / ld[a];
        double tb = (half[a] - lo_[a]) / ld[a];
        if (ta > tb) std::swap(ta, tb);
        if (ta > t0) {
          t0 = ta;
          axis = a;
        }
        t1 = std::min(t1, tb);
        if (t0 > t1) return false;
      }
      if (axis < 0) return false;  // starts inside
      hit.distance = t0;
      hit.cos_incidence = std::abs(ld[axis]);
      hit.side = axis < 2;
      hit.below_top = p.z1 - (o.z() + t0 * d.z());
      break;
    }
    case Primitive::Shape::cylinder: {
      const double ox = o.x() - p.c.x();
      const double oy = o.y() - p.c.y();
      const double a = d.x() * d.x() + d.y() * d.y();
      if (a < 1e-12) return false;
      const double b = ox * d.x() + oy * d.y();
      const double c = ox * ox + oy * oy - p.radius * p.radius;
      const double disc = b * b - a * c;
      if (disc < 0) return false;
      const double sq = std::sqrt(disc);
      const double t_in = (-b - sq) / a;
      const double t_out = (-b + sq) / a;
      if (t_in < t_lo || t_in > t_hi) {
        // The top cap, seen from above.
        if (d.z() >= 0) return false;
        const double tc = (p.z1 - o.z()) / d.z();
        if (tc < std::max(t_lo, t_in) || tc > std::min(t_hi, t_out)) return false;
        hit.distance = tc;
        hit.cos_incidence = -d.z();
        break;
      }
      const double z = o.z() + t_in * d.z();
      if (z < p.z0) return false;
      if (z > p.z1) {
        if (d.z() >= 0) return false;
        const double tc = (p.z1 - o.z()) / d.z();
        if (tc > std::min(t_hi, t_out)) return false;
        hit.distance = tc;
        hit.cos_incidence = -d.z();
        break;
      }
      hit.distance = t_in;
      const double nx = (ox + t_in * d.x()) / p.radius;
      const double ny = (oy + t_in * d.y()) / p.radius;
      hit.cos_incidence = std::abs(nx * d.x() + ny * d.y());
      hit.side = true;
      hit.below_top = p.z1 - z;
      break;
    }
    case Primitive::Shape::ellipsoid: {
      const Vec3 os = (o - p.c).cwiseQuotient(p.half);
      const Vec3 ds = d.cwiseQuotient(p.half);
      const double a = ds.squaredNorm();
      const double b = os.dot(ds);
      const double c = os.squaredNorm() - 1.0;
      const double disc = b * b - a * c;
      if (disc < 0) return false;
      const double sq = std::sqrt(disc);
      const double t_in = std::max((-b - sq) / a, t_lo);
      const double t_out = std::min((-b + sq) / a, t_hi);
      if (t_in >= t_out) return false;
      const double u = unit(hash(ray_key, 0xC0FFEEull + static_cast<std::uint64_t>(&p - primitives_.data())));
      const double s = -std::log1p(-u) / kCanopyDensity;
      if (t_in + s >= t_out) return false;
      hit.distance = t_in + s;
      hit.cos_incidence = 0.3 + 0.7 * unit(hash(ray_key, 0xC1));
      hit.kind = HitKind::canopy;
      hit.terrain = TerrainClass::vegetation;
      hit.reflectivity = p.remission + 8.0 * gaussian(hash(ray_key, 0xC2));
      hit.hit = true;
      return true;
    }
  }
  hit.kind = HitKind::object;
  hit.terrain = p.terrain;
  hit.reflectivity = p.remission + 3.0 * gaussian(hash(ray_key, 0xC3));
  hit.hit = true;
  return true;
}

Hit World::cast(const Vec3& o, const Vec3& d, double min_range, double max_range, std::uint64_t ray_key) const noexcept {
  Hit best;
  double best_t = max_range;
  bool medium_seen = false;

  // Clip to the grid's footprint.
  const double xmin = x0_, xmax = x0_ + (nx_ - 1) * res_;
  const double ymin = y0_, ymax = y0_ + (ny_ - 1) * res_;
  double t0 = min_range, t1 = max_range;
  auto clip = [&](double oc, double dc, double lo, double hi) {
    if (std::abs(dc) < 1e-12) return oc >= lo && oc <= hi;
    double ta = (lo - oc) / dc, tb = (hi - oc) / dc;
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    return t0 <= t1;
  };
  if (!clip(o.x(), d.x(), xmin, xmax) || !clip(o.y(), d.y(), ymin, ymax)) return best;
  // Above everything and rising: nothing to hit.
  if (d.z() > 0) {
    const double t_top = (z_top_ - o.z()) / d.z();
    if (t_top < t0) return best;
    t1 = std::min(t1, std::max(t_top, t0));
  }
  t1 = std::min(t1 * (1 + 1e-12), max_range);

  const double du = d.x() * inv_res_;
  const double dv = d.y() * inv_res_;
  const double ou = (o.x() - x0_) * inv_res_;
  const double ov = (o.y() - y0_) * inv_res_;
  const int nqu = nx_ - 1;
  const int nqv = ny_ - 1;

  Dda blocks;
  blocks.start(ou + t0 * du, ov + t0 * dv, du, dv, t0, kBlock, bx_, by_);
  double tb0 = t0;
  while (tb0 < t1 && tb0 < best_t) {
    const double tb1 = std::min({blocks.exit(), t1, best_t});
    const std::size_t b = static_cast<std::size_t>(blocks.j) * static_cast<std::size_t>(bx_) + static_cast<std::size_t>(blocks.i);
    const double za = o.z() + tb0 * d.z();
    const double zb = o.z() + tb1 * d.z();
    if (std::min(za, zb) <= block_max_[b]) {
      // Primitives in this block.
      for (std::uint32_t k = block_first_[b]; k < block_first_[b + 1]; ++k) {
        Hit h;
        if (intersect(primitives_[block_items_[k]], o, d, min_range, best_t, ray_key, h) && h.distance < best_t) {
          best_t = h.distance;
          best = h;
        }
      }
      // The ground and the medium, quad by quad.
      Dda q;
      q.start(ou + tb0 * du, ov + tb0 * dv, du, dv, tb0, 1.0, nqu, nqv);
      double ta = tb0;
      const double t_end = std::min(tb1, best_t);
      while (ta < t_end) {
        const double tq = std::min(q.exit(), t_end);
        const int i = q.i, j = q.j;
        const std::size_t i00 = index(i, j);
        const std::size_t i10 = i00 + 1;
        const std::size_t i01 = i00 + static_cast<std::size_t>(nx_);
        const std::size_t i11 = i01 + 1;
        const double z0 = o.z() + ta * d.z();
        const double z1 = o.z() + tq * d.z();
        const float qmax = std::max({h_[i00] + med_[i00], h_[i10] + med_[i10], h_[i01] + med_[i01], h_[i11] + med_[i11]});
        if (std::min(z0, z1) <= qmax) {
          auto height = [&](double t) {
            const double f = std::clamp(ou + t * du - i, 0.0, 1.0);
            const double g = std::clamp(ov + t * dv - j, 0.0, 1.0);
            return (h_[i00] * (1 - f) + h_[i10] * f) * (1 - g) + (h_[i01] * (1 - f) + h_[i11] * f) * g;
          };
          const double fa = z0 - height(ta);
          const double fb = z1 - height(tq);
          double t_ground = kInf;
          if (fa < 0) t_ground = ta;
          else if (fb < 0) t_ground = ta + (tq - ta) * fa / (fa - fb);
          // The medium of the quad's nearest sample.
          const double tm = 0.5 * (ta + tq);
          const int si = std::clamp(static_cast<int>(std::lround(ou + tm * du)), 0, nx_ - 1);
          const int sj = std::clamp(static_cast<int>(std::lround(ov + tm * dv)), 0, ny_ - 1);
          const std::size_t sidx = index(si, sj);
          const double m = med_[sidx];
          if (m > 0) {
            const double te = std::min(t_ground, tq);
            const double ga = fa - m;
            const double gb = (t_ground < kInf ? 0.0 : fb) - m;
            if (ga < 0 || gb < 0) {
              const double cross = ga != gb ? ta + (te - ta) * ga / (ga - gb) : ta;
              const double t_in = ga < 0 ? ta : cross;
              const double t_out = gb < 0 ? te : cross;
              if (t_out > t_in) {
                medium_seen = true;
                const double u = unit(hash(ray_key, sidx));
                const double s = -std::log1p(-u) / dens_[sidx];
                if (t_in + s < t_out && t_in + s >= min_range) {
                  const double t = t_in + s;
                  if (t < best_t) {
                    best_t = t;
                    best.hit = true;
                    best.distance = t;
                    best.kind = HitKind::medium;
                    best.terrain = static_cast<TerrainClass>(cls_[sidx]);
                    const Material& mat = materials_[cls_[sidx]];
                    best.reflectivity = mat.remission_mean + mat.remission_std * gaussian(hash(ray_key, 0xB1ADE));
                    best.cos_incidence = 0.3 + 0.7 * unit(hash(ray_key, 0xB1ADF));
                    best.through_medium = true;
                    best.side = false;
                  }
                  t_ground = kInf;
                }
              }
            }
          }
          if (t_ground < kInf && t_ground < best_t && t_ground >= min_range) {
            best_t = t_ground;
            best.hit = true;
            best.distance = t_ground;
            best.kind = HitKind::ground;
            const double ug = ou + t_ground * du, vg = ov + t_ground * dv;
            const double f = std::clamp(ug - i, 0.0, 1.0);
            const double g = std::clamp(vg - j, 0.0, 1.0);
            const double hx = ((h_[i10] - h_[i00]) * (1 - g) + (h_[i11] - h_[i01]) * g) * inv_res_;
            const double hy = ((h_[i01] - h_[i00]) * (1 - f) + (h_[i11] - h_[i10]) * f) * inv_res_;
            const double inv = 1.0 / std::sqrt(hx * hx + hy * hy + 1.0);
            best.cos_incidence = std::abs(-hx * d.x() - hy * d.y() + d.z()) * inv;
            const int gi = std::clamp(static_cast<int>(std::lround(ug)), 0, nx_ - 1);
            const int gj = std::clamp(static_cast<int>(std::lround(vg)), 0, ny_ - 1);
            best.terrain = static_cast<TerrainClass>(cls_[index(gi, gj)]);
            best.reflectivity = refl_[index(gi, gj)];
            best.through_medium = medium_seen;
            best.side = false;
          }
        }
        if (best_t <= tq) break;
        ta = tq;
        q.step();
        if (q.i < 0 || q.j < 0 || q.i >= nqu || q.j >= nqv) break;
      }
    }
    tb0 = tb1;
    if (tb0 >= t1 || tb0 >= best_t) break;
    blocks.step();
    if (blocks.i < 0 || blocks.j < 0 || blocks.i >= bx_ || blocks.j >= by_) break;
  }
  if (best.hit) best.through_medium = best.through_medium || medium_seen;
  return best;
}

}  // namespace trailnav::sim
