#include "trailnav/perception/terrain_mapper.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

#include "trailnav/runtime/prefetch.hpp"

namespace trailnav::perception {

std::string check_terrain_alignment(const TerrainConfig& config, const FeatureParams& alignment) {
  if (config.min_range >= alignment.min_range && config.max_range <= alignment.max_range) return {};
  char text[320];
  std::snprintf(text, sizeof text,
                "min_range..max_range %.6g..%.6g m reaches outside the %.6g..%.6g m of obstacles.features: the terrain "
                "registers the points the obstacle pipeline aligned, so its range must lie within theirs",
                static_cast<double>(config.min_range), static_cast<double>(config.max_range),
                static_cast<double>(alignment.min_range), static_cast<double>(alignment.max_range));
  return text;
}

TerrainMapper::Created TerrainMapper::create(const TerrainConfig& config, const MountParams& mount,
                                             const velodyne::RangeImageShape& shape, const RandomForest* forest,
                                             const FeatureParams& alignment) {
  if (std::string problem = check_terrain_config(config); !problem.empty()) return {nullptr, problem};
  if (std::string problem = check_terrain_alignment(config, alignment); !problem.empty()) return {nullptr, problem};
  if (shape.rings < 1 || shape.max_columns < 8) {
    return {nullptr, "range images of " + std::to_string(shape.rings) + " rings x " + std::to_string(shape.max_columns) +
                         " columns are too small for terrain analysis"};
  }
  return {std::unique_ptr<TerrainMapper>(new TerrainMapper(config, mount, shape, forest, alignment)), {}};
}

TerrainMapper::TerrainMapper(const TerrainConfig& config, const MountParams& mount,
                             const velodyne::RangeImageShape& shape, const RandomForest* forest,
                             const FeatureParams& alignment)
    : config_(config),
      aligner_(mount, alignment),
      cloud_(CloudShape{shape.rings, shape.max_columns, false}),
      forest_(forest),
      work_(config.map.size_x, config.map.size_y, config.map.resolution),
      map_(config.map),
      area_cells_(new AreaSums[static_cast<std::size_t>(work_.size_x())]),
      area_rows_(new AreaSums[static_cast<std::size_t>(work_.size_x()) * (2 * kAreaRadius + 1)]),
      area_cols_(new AreaSums[static_cast<std::size_t>(work_.size_x())]) {}

TerrainCounters TerrainMapper::counters() const noexcept {
  TerrainCounters c = counters_;
  c.align = aligner_.counters();
  return c;
}

void TerrainMapper::copy_state_from(const TerrainMapper& other) noexcept {
  work_.assign_from(other.work_);
  map_.copy_from(other.map_);
  counters_ = other.counters_;
  have_step_ = other.have_step_;
  step_x_ = other.step_x_;
  step_y_ = other.step_y_;
  step_ns_ = other.step_ns_;
  robot_x_ = other.robot_x_;
  robot_y_ = other.robot_y_;
  time_ns_ = other.time_ns_;
  clock_offset_ns_ = other.clock_offset_ns_;
}

bool TerrainMapper::process(const velodyne::RangeImage& image, const PoseTrack* poses) noexcept {
  align(image, poses);
  register_cloud();
  if (!step_due()) return false;
  step(cloud_.time_ns);
  return true;
}

bool TerrainMapper::process_aligned(const RevolutionCloud& aligned) noexcept {
  ++counters_.revolutions;
  register_cloud(aligned);
  if (!step_due()) return false;
  step(aligned.time_ns);
  return true;
}

void TerrainMapper::align(const velodyne::RangeImage& image, const PoseTrack* poses) noexcept {
  aligner_.align(image, poses, cloud_);
  ++counters_.revolutions;
}

void TerrainMapper::register_cloud(const RevolutionCloud& cloud) noexcept {
  robot_x_ = cloud.robot_x;
  robot_y_ = cloud.robot_y;
  time_ns_ = cloud.time_ns;
  if (sums_sink_ != nullptr) sums_sink_->robot_pose(cloud.robot_x, cloud.robot_y, cloud.robot_yaw, cloud.time_ns);
  clock_offset_ns_ = cloud.clock_offset_ns;
  // Both grids follow the robot together, so a cell and its class share a
  // world index; cells leaving the map are forgotten by both.
  work_.move_to(cloud.robot_x, cloud.robot_y);
  map_.grid().move_to(cloud.robot_x, cloud.robot_y);
  const double res = work_.resolution();
  const double inv = 1.0 / res;
  const CellIndex lo = work_.origin();
  // Cell coordinates relative to the grid's origin, in float from the
  // reference point (as the obstacle map does): a point's cell is
  // (offset + x / resolution), no per-point double floor of a large number.
  const auto ox = static_cast<float>(cloud.ref_x * inv - lo.x);
  const auto oy = static_cast<float>(cloud.ref_y * inv - lo.y);
  const auto finv = static_cast<float>(inv);
  const auto fres = static_cast<float>(res);
  const auto size_x = static_cast<float>(work_.size_x());
  const auto size_y = static_cast<float>(work_.size_y());
  const auto ref_z = static_cast<float>(cloud.ref_z);
  const float min_range = config_.min_range, max_range = config_.max_range;
  std::uint64_t registered = 0, outside = 0, out_of_range = 0;
  // In batches, as the obstacle map: first each point's cell is found and
  // its sums are fetched ahead (the grid is megabytes; a cell's sums span two
  // cache lines), then the batch is added.
  constexpr std::size_t kBatch = 128;
  struct Point {
    std::uint32_t cell;
    float x, y, z, r;
  };
  std::array<Point, kBatch> batch;
  std::size_t n = 0;
  const auto add_batch = [&]() noexcept {
    for (std::size_t b = 0; b < n; ++b) {
      const Point& p = batch[b];
      work_.at_offset(p.cell).stats.add(p.x, p.y, p.z, p.r);
    }
    registered += n;
    n = 0;
  };
  for (int ring = 0; ring < cloud.rings(); ++ring) {
    const std::size_t row = cloud.index(ring, 0);
    for (int col = 0; col < cloud.columns(); ++col) {
      const std::size_t k = row + static_cast<std::size_t>(col);
      if (cloud.state[k] == PointState::none) continue;
      if (cloud.range[k] < min_range || cloud.range[k] > max_range) {
        ++out_of_range;
        continue;
      }
      const float lx = ox + cloud.x[k] * finv;
      const float ly = oy + cloud.y[k] * finv;
      if (!(lx >= 0.0f && lx < size_x && ly >= 0.0f && ly < size_y)) {
        ++outside;
        continue;
      }
      const auto ix = static_cast<std::int32_t>(lx);
      const auto iy = static_cast<std::int32_t>(ly);
      const std::size_t offset = work_.offset_from_origin(ix, iy);
      const auto* bytes = reinterpret_cast<const char*>(&work_.at_offset(offset).stats);
      prefetch_for_write(bytes);
      prefetch_for_write(bytes + sizeof(CellStats) - 1);
      // The point from its cell's centre.
      batch[n] = {static_cast<std::uint32_t>(offset), (lx - static_cast<float>(ix) - 0.5f) * fres,
                  (ly - static_cast<float>(iy) - 0.5f) * fres, cloud.z[k] + ref_z, cloud.intensity[k]};
      if (++n == kBatch) add_batch();
    }
  }
  add_batch();
  counters_.points += registered;
  counters_.outside += outside;
  counters_.out_of_range += out_of_range;
}

bool TerrainMapper::step_due() const noexcept {
  if (!have_step_) return true;  // the first revolution starts the first interval
  const double moved = std::hypot(robot_x_ - step_x_, robot_y_ - step_y_);
  if (moved >= config_.step_distance) return true;
  return config_.max_step_interval > 0.0 &&
         static_cast<double>(time_ns_ - step_ns_) >= config_.max_step_interval * 1e9;
}

void TerrainMapper::step(std::int64_t now_ns) noexcept {
  if (!have_step_) {
    // The first revolution only opens the first interval: points keep
    // accumulating until the robot has moved d.
    have_step_ = true;
    step_x_ = robot_x_;
    step_y_ = robot_y_;
    step_ns_ = now_ns;
    return;
  }
  step_x_ = robot_x_;
  step_y_ = robot_y_;
  step_ns_ = now_ns;
  ++counters_.steps;
  if (sums_sink_ != nullptr) sums_sink_->step_begins(robot_x_, robot_y_, now_ns, map_);
  const CellIndex o = work_.origin();
  const std::int32_t nx = work_.size_x(), ny = work_.size_y();
  constexpr std::int32_t kR = kAreaRadius;
  // One pass over the grid. Row y's remission sums enter the area sums kR
  // rows before its cells are visited, so the areas of row y - kR are
  // complete when it is; a cell's sums are cleared (when it gets its
  // feature) only after they entered.
  std::fill(area_cols_.get(), area_cols_.get() + nx, AreaSums{});
  // Cells due for a feature are batched: their features are computed four at
  // a time on four-wide vectors, then the forest walks them one by one.
  std::uint64_t classified = 0, known = 0;
  std::size_t pending = 0;
  for (std::int32_t y = 0; y < ny + kR; ++y) {
    if (y < ny) add_area_row(y);
    const std::int32_t row = y - kR;
    if (row < 0) continue;
    work_.for_each_in_window({o.x, o.y + row}, {o.x + nx, o.y + row + 1}, [&](CellIndex i, TerrainWorkCell& w) {
      TerrainCell& c = map_.grid().at(i);
      if ((w.stats.n > 0 || w.frozen) && due_for_feature(w, c, i, now_ns)) {
        batch_[pending++] = {&w, &c, i, {}, area_std(i.x - o.x)};
        if (pending == batch_.size()) {
          finish_batch(pending, now_ns, classified, known);
          pending = 0;
        }
        return;
      }
      classified += w.frozen ? 1 : 0;
      known += c.known ? 1 : 0;
    });
    if (row - kR >= 0) drop_area_row(row - kR);
  }
  finish_batch(pending, now_ns, classified, known);
  counters_.classified_cells = classified;
  counters_.known_cells = known;
  map_.sequence = counters_.steps;
  map_.time_ns = now_ns;
  map_.clock_offset_ns = clock_offset_ns_;
}

void TerrainMapper::add_area_row(std::int32_t y) noexcept {
  constexpr std::int32_t kR = kAreaRadius;
  const std::int32_t nx = work_.size_x();
  const auto sx = static_cast<std::size_t>(nx);
  AreaSums* cells = area_cells_.get();
  AreaSums* cols = area_cols_.get();
  const CellIndex o = work_.origin();
  work_.for_each_in_window({o.x, o.y + y}, {o.x + nx, o.y + y + 1}, [&](CellIndex i, const TerrainWorkCell& w) {
    // The cell keeps its sums shifted by its first remission r0.
    const double n = w.stats.n, r0 = w.stats.r0, sr = w.stats.sr, srr = w.stats.srr;
    cells[i.x - o.x] = {n, n * r0 + sr, n * r0 * r0 + 2.0 * r0 * sr + srr};
  });
  // Sums along x over the kR cells each side, kept in the ring until the row
  // leaves the column sums.
  AreaSums* h = area_rows_.get() + static_cast<std::size_t>(y % (2 * kR + 1)) * sx;
  AreaSums run{};
  for (std::int32_t x = 0; x < std::min(kR, nx); ++x) {
    run.n += cells[x].n;
    run.s += cells[x].s;
    run.q += cells[x].q;
  }
  for (std::int32_t x = 0; x < nx; ++x) {
    if (x + kR < nx) {
      run.n += cells[x + kR].n;
      run.s += cells[x + kR].s;
      run.q += cells[x + kR].q;
    }
    h[x] = run;
    cols[x].n += run.n;
    cols[x].s += run.s;
    cols[x].q += run.q;
    if (x - kR >= 0) {
      run.n -= cells[x - kR].n;
      run.s -= cells[x - kR].s;
      run.q -= cells[x - kR].q;
    }
  }
}

void TerrainMapper::drop_area_row(std::int32_t y) noexcept {
  const auto sx = static_cast<std::size_t>(work_.size_x());
  const AreaSums* h = area_rows_.get() + static_cast<std::size_t>(y % (2 * kAreaRadius + 1)) * sx;
  AreaSums* cols = area_cols_.get();
  for (std::size_t x = 0; x < sx; ++x) {
    cols[x].n -= h[x].n;
    cols[x].s -= h[x].s;
    cols[x].q -= h[x].q;
  }
}

float TerrainMapper::area_std(std::int32_t x) const noexcept {
  const AreaSums& a = area_cols_[static_cast<std::size_t>(x)];
  // Counts are whole numbers, exact in double; the other sums may keep a
  // rounding residue of what left the box.
  if (a.n < 0.5) return 0.0f;
  const double mean = a.s / a.n;
  return static_cast<float>(std::sqrt(std::max(0.0, a.q / a.n - mean * mean)));
}

bool TerrainMapper::due_for_feature(TerrainWorkCell& w, TerrainCell& c, CellIndex i, std::int64_t now_ns) noexcept {
  if (w.frozen && config_.reopen_after > 0.0 && static_cast<double>(now_ns - w.frozen_ns) >= config_.reopen_after * 1e9) {
    // Open the cell again (§7.2.3), softened so new evidence can move it.
    w.frozen = false;
    w.observations = 0;
    std::array<float, kTerrainClasses> p = c.p;
    for (float& v : p) v = 0.8f * v + 0.2f / kTerrainClasses;
    c.set(p);
    ++counters_.reopened;
  }
  if (w.stats.n < static_cast<std::uint32_t>(config_.min_points)) return false;  // keeps accumulating
  if (w.frozen && observer_ == nullptr) {
    ++counters_.frozen_skipped;
    if (sums_sink_ != nullptr) {
      const WorldPoint centre = work_.cell_center(i);
      sums_sink_->cell_sums(i, w.stats, nullptr, centre.x, centre.y);
    }
    w.stats = CellStats{};
    return false;
  }
  return true;
}

void TerrainMapper::finish_batch(std::size_t count, std::int64_t now_ns, std::uint64_t& classified,
                                 std::uint64_t& known) noexcept {
  std::array<FeatureVector, 4> features;
  for (std::size_t k = 0; k < count; k += 4) {
    // A short last group repeats its last cell in the lanes it lacks.
    std::array<const CellStats*, 4> cells;
    for (std::size_t l = 0; l < 4; ++l) cells[l] = &batch_[std::min(k + l, count - 1)].work->stats;
    compute_terrain_features(cells, features);
    for (std::size_t l = 0; l < 4 && k + l < count; ++l) {
      batch_[k + l].feature = features[l];
      batch_[k + l].feature[static_cast<int>(TerrainFeature::area_std_remission)] = batch_[k + l].area_std;
    }
  }
  for (std::size_t k = 0; k < count; ++k) {
    Pending& b = batch_[k];
    update_cell(*b.work, *b.cell, b.index, b.feature, now_ns);
    classified += b.work->frozen ? 1 : 0;
    known += b.cell->known ? 1 : 0;
  }
}

void TerrainMapper::update_cell(TerrainWorkCell& w, TerrainCell& c, CellIndex i, const FeatureVector& feature,
                                std::int64_t now_ns) noexcept {
  TerrainObservation obs;
  obs.feature = feature;
  if (forest_ != nullptr) {
    forest_->predict(obs.feature, obs.likelihood);
  } else {
    obs.likelihood.fill(1.0f / kTerrainClasses);
  }
  if (w.frozen) {
    ++counters_.frozen_skipped;
  } else if (forest_ != nullptr) {
    // Eq. 7.15 with a uniform prior: P(t | f_1..n) ∝ P(t | f_n) P(t | f_1..n-1).
    std::array<float, kTerrainClasses> p{};
    float sum = 0.0f;
    for (int t = 0; t < kTerrainClasses; ++t) {
      const auto k = static_cast<std::size_t>(t);
      const float prior = c.known ? c.p[k] : 1.0f / kTerrainClasses;
      p[k] = std::max(obs.likelihood[k], config_.min_likelihood) * prior;
      sum += p[k];
    }
    for (float& v : p) v = std::max(v / sum, config_.min_probability);
    c.set(p);
    ++counters_.features;
    if (w.observations < 0xFFFF) ++w.observations;
    if (w.observations > config_.freeze_observations && c.p[static_cast<std::size_t>(c.best)] > config_.freeze_probability) {
      w.frozen = true;
      w.frozen_ns = now_ns;
      ++counters_.frozen;
    }
    obs.updated = true;
  }
  if (observer_ != nullptr) {
    obs.cell = i;
    const WorldPoint centre = work_.cell_center(i);
    obs.x = centre.x;
    obs.y = centre.y;
    obs.points = w.stats.n;
    obs.estimate = &c;
    obs.time_ns = now_ns;
    observer_->observe(obs);
  }
  if (sums_sink_ != nullptr) {
    const WorldPoint centre = work_.cell_center(i);
    sums_sink_->cell_sums(i, w.stats, &feature, centre.x, centre.y);
  }
  w.stats = CellStats{};
}

}  // namespace trailnav::perception
