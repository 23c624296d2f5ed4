#include "trailnav/perception/obstacle_map.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "trailnav/runtime/prefetch.hpp"

namespace trailnav::perception {

ObstacleMap::ObstacleMap(const MapParams& params, FusionModel model)
    : params_(params),
      model_(model),
      percent_scale_(kPercentSteps / std::max(params.logit_max - params.logit_min, 1e-6f)),
      grid_(params.size, params.size, params.resolution, ObstacleCell{}),
      occupancy_(params.size, params.size, params.resolution, std::int8_t{-1}),
      hits_(model == FusionModel::pw ? params.size : 1, model == FusionModel::pw ? params.size : 1, params.resolution,
            DiracHit{}),
      occupied_logit_(logit(params.occupied)),
      prior_logit_(logit(params.prior)) {
  for (int i = 0; i <= kPercentSteps; ++i) {
    const float l = params.logit_min + (params.logit_max - params.logit_min) * static_cast<float>(i) / kPercentSteps;
    percent_[static_cast<std::size_t>(i)] = static_cast<std::int8_t>(std::lround(100.0f * logistic(l)));
  }
}

void ObstacleMap::integrate(const RevolutionCloud& cloud, const ObstacleModels& models, const TerrainSource& terrain) noexcept {
  begin_revolution(cloud, models);
  integrate_columns(cloud, models, terrain, 0, cloud.columns());
}

void ObstacleMap::begin_revolution(const RevolutionCloud& cloud, const ObstacleModels& models) noexcept {
  ++revolution_;
  // The hold of PW maps, in revolutions at the rate measured so far.
  if (revolution_ == 1) first_ns_ = cloud.start_ns;
  last_ns_ = cloud.start_ns;
  const double period_s = revolution_ > 1 ? static_cast<double>(last_ns_ - first_ns_) * 1e-9 / (revolution_ - 1) : 0.1;
  const auto revolutions_in = [&](float seconds) {
    return static_cast<std::uint32_t>(std::lround(static_cast<double>(seconds) / std::max(period_s, 1e-3)));
  };
  hold_revolutions_ = revolutions_in(params_.dirac_hold_s);
  for (int t = 0; t < kTerrainClasses; ++t) {
    top_hold_revolutions_[static_cast<std::size_t>(t)] = revolutions_in(models.top_hold_s(t));
  }
  // Centred on where the robot was when the revolution began: its points
  // may go in before it ends.
  counters_.cells_cleared += grid_.move_to(cloud.start_robot_x, cloud.start_robot_y);
  occupancy_.move_to(cloud.start_robot_x, cloud.start_robot_y);
  if (model_ == FusionModel::pw) hits_.move_to(cloud.start_robot_x, cloud.start_robot_y);
}

void ObstacleMap::integrate_columns(const RevolutionCloud& cloud, const ObstacleModels& models, const TerrainSource& terrain,
                                    int first, int end) noexcept {
  first = std::max(first, 0);
  end = std::min(end, cloud.columns());
  if (first >= end) return;
  switch (model_) {
    case FusionModel::pw: integrate_points<FusionModel::pw>(cloud, models, terrain, first, end); break;
    case FusionModel::ps: integrate_points<FusionModel::ps>(cloud, models, terrain, first, end); break;
    case FusionModel::pc: integrate_points<FusionModel::pc>(cloud, models, terrain, first, end); break;
  }
}

template <FusionModel M>
void ObstacleMap::integrate_points(const RevolutionCloud& cloud, const ObstacleModels& models,
                                   const TerrainSource& terrain, int first, int end) noexcept {
  const float lo = params_.logit_min;
  const float hi = params_.logit_max;
  const float prior = prior_logit_;
  const std::uint32_t now = revolution_;
  const std::uint32_t hold = hold_revolutions_;
  const float clear_depth = params_.dirac_clear_depth;
  const auto ref_z = static_cast<float>(cloud.ref_z);
  // Cell coordinates relative to the map's origin: a point's cell is
  // (offset + x / resolution), so no per-point floor of a large number.
  const double inv = 1.0 / grid_.resolution();
  const CellIndex origin = grid_.origin();
  const auto ox = static_cast<float>(cloud.ref_x * inv - origin.x);
  const auto oy = static_cast<float>(cloud.ref_y * inv - origin.y);
  const auto finv = static_cast<float>(inv);
  const auto size = static_cast<float>(grid_.size_x());
  const auto size_y = static_cast<float>(grid_.size_y());

  const TerrainClassMap* tmap = terrain.adaptive_map();
  const int fixed_cls = static_cast<int>(terrain.fallback());
  TerrainCell unknown_cell;
  unknown_cell.p[static_cast<std::size_t>(fixed_cls)] = 1.0f;
  unknown_cell.best = static_cast<TerrainClass>(fixed_cls);
  unknown_cell.known = true;
  double t_inv = 1.0;
  float tox = 0.0f, toy = 0.0f, tsize_x = 0.0f, tsize_y = 0.0f;
  CellIndex torigin{};
  if (tmap != nullptr) {
    const auto& tg = tmap->grid();
    t_inv = 1.0 / tg.resolution();
    torigin = tg.origin();
    tox = static_cast<float>(cloud.ref_x * t_inv - torigin.x);
    toy = static_cast<float>(cloud.ref_y * t_inv - torigin.y);
    tsize_x = static_cast<float>(tg.size_x());
    tsize_y = static_cast<float>(tg.size_y());
  }
  const auto tfinv = static_cast<float>(t_inv);

  std::uint64_t updates = 0, outside = 0, unknown = 0;
  // The points go through in batches. First each point's cells are found and
  // fetched ahead (prefetch); then the batch is integrated, by when they are
  // in the cache. A revolution's cells are spread over megabytes, and the
  // alignment and the features stream through the cache between two updates.
  constexpr std::size_t kBatch = 128;
  constexpr std::uint32_t kNoTerrain = std::numeric_limits<std::uint32_t>::max();
  std::array<std::uint32_t, kBatch> batch_point;
  std::array<std::uint32_t, kBatch> batch_cell;
  std::array<std::uint32_t, kBatch> batch_terrain;
  std::size_t batch = 0;

  const auto integrate_batch = [&]() noexcept {
    for (std::size_t b = 0; b < batch; ++b) {
      const std::size_t k = batch_point[b];
      const std::size_t offset = batch_cell[b];
      const TerrainCell* tc = &unknown_cell;
      if (tmap != nullptr) {
        const TerrainCell* c = batch_terrain[b] == kNoTerrain ? nullptr : &tmap->grid().at_offset(batch_terrain[b]);
        if (c != nullptr && c->known) {
          tc = c;
        } else {
          ++unknown;
        }
      }
      ObstacleCell& cell = grid_.at_offset(offset);
      const float h = cloud.step_height[k];
      const float s = cloud.sin_incline[k];
      // A cell's first point starts from the prior.
      const float before = std::isnan(cell.logit) ? prior : cell.logit;
      if constexpr (M == FusionModel::pw) {
        DiracHit& hit = hits_.at_offset(offset);
        const float z = ref_z + cloud.z[k];
        const int cls = static_cast<int>(tc->best);
        if (models.dirac(cls, h, s)) {
          hit.top = (before == hi && hit.revolution != 0) ? std::max(hit.top, z) : z;
          hit.revolution = now;
          cell.logit = hi;
        } else if (hit.revolution == 0 ||
                   (now - hit.revolution > hold &&
                    (z < hit.top - clear_depth ||
                     now - hit.revolution > top_hold_revolutions_[static_cast<std::size_t>(cls)]))) {
          // Free ground below where the obstacle stood clears it once the hold
          // is over; the flat top of a box (as high as its faces) does not.
          cell.logit = lo;
        } else {
          cell.logit = before;
        }
      } else if constexpr (M == FusionModel::ps) {
        const float p = models.smooth(static_cast<int>(tc->best), h, s);
        cell.logit = std::clamp(before + models.increment(p), lo, hi);
      } else {
        const int hi_index = ObstacleModels::step_index(h);
        const int si_index = ObstacleModels::sin_index(s);
        float p = 0.0f;
        // No branch on zero weights: a class of weight 0 adds exactly 0.
        for (int t = 0; t < kTerrainClasses; ++t) {
          p += tc->p[static_cast<std::size_t>(t)] * models.step_part(t, hi_index) * models.incline_part(t, si_index);
        }
        cell.logit = std::clamp(before + models.increment(p), lo, hi);
      }
      occupancy_.at_offset(offset) = percent(cell.logit);
    }
    updates += batch;
    batch = 0;
  };

  for (int ring = 0; ring < cloud.rings(); ++ring) {
    const std::size_t base = cloud.index(ring, 0);
    for (int j = first; j < end; ++j) {
      const std::size_t k = base + static_cast<std::size_t>(j);
      const PointState st = cloud.state[k];
      if (st != PointState::measured && st != PointState::flat) continue;
      const float lx = ox + cloud.x[k] * finv;
      const float ly = oy + cloud.y[k] * finv;
      if (!(lx >= 0.0f && lx < size && ly >= 0.0f && ly < size_y)) {
        ++outside;
        continue;
      }
      const std::size_t offset = grid_.offset_from_origin(static_cast<std::int32_t>(lx), static_cast<std::int32_t>(ly));
      prefetch_for_write(&grid_.at_offset(offset));
      prefetch_for_write(&occupancy_.at_offset(offset));
      if constexpr (M == FusionModel::pw) prefetch_for_write(&hits_.at_offset(offset));
      std::uint32_t toffset = kNoTerrain;
      if (tmap != nullptr) {
        const float tx = tox + cloud.x[k] * tfinv;
        const float ty = toy + cloud.y[k] * tfinv;
        if (tx >= 0.0f && tx < tsize_x && ty >= 0.0f && ty < tsize_y) {
          const std::size_t t = tmap->grid().offset_from_origin(static_cast<std::int32_t>(tx), static_cast<std::int32_t>(ty));
          prefetch_for_read(&tmap->grid().at_offset(t));
          toffset = static_cast<std::uint32_t>(t);
        }
      }
      batch_point[batch] = static_cast<std::uint32_t>(k);
      batch_cell[batch] = static_cast<std::uint32_t>(offset);
      batch_terrain[batch] = toffset;
      if (++batch == kBatch) integrate_batch();
    }
  }
  integrate_batch();
  counters_.updates += updates;
  counters_.outside_map += outside;
  counters_.unknown_terrain += unknown;
}

void ObstacleMap::export_occupancy(std::span<std::int8_t> out) const noexcept {
  if (out.size() >= occupancy_.cell_count()) occupancy_.copy_to(out);
}

}  // namespace trailnav::perception
