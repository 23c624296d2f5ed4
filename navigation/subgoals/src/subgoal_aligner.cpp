#include "trailnav/navigation/subgoals/subgoal_aligner.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace trailnav::subgoals {
namespace {

// Standard normal quantile by bisection on the CDF (construction only).
double normal_quantile(double p) {
  double lo = -10.0, hi = 10.0;
  for (int i = 0; i < 100; ++i) {
    const double mid = 0.5 * (lo + hi);
    (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

std::uint64_t rotl(std::uint64_t x, int k) noexcept { return (x << k) | (x >> (64 - k)); }

std::uint64_t splitmix(std::uint64_t& s) noexcept {
  std::uint64_t z = (s += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

}  // namespace

std::string check_aligner_config(const AlignerConfig& c) {
  if (c.samples < 1 || c.samples > 50000) return "samples must be 1..50000 (is " + std::to_string(c.samples) + ")";
  if (c.sequence < 1 || c.sequence > kMaxSequence)
    return "sequence (K) must be 1.." + std::to_string(kMaxSequence) + " (is " + std::to_string(c.sequence) + ")";
  if (c.neighbourhood < 0 || c.neighbourhood > 10) return "neighbourhood (N) must be 0..10";
  if (!(c.lambda > 0.0 && c.lambda <= 100.0)) return "lambda must be in (0, 100]";
  if (!(c.sigma_d >= 0.0 && c.sigma_d <= 5.0)) return "sigma_d must be 0..5 m";
  if (!(c.sigma_theta >= 0.0 && c.sigma_theta <= 0.4)) return "sigma_theta must be 0..0.4 rad";
  if (!(c.sigma_along >= 0.0 && c.sigma_along <= 50.0) || !(c.sigma_across >= 0.0 && c.sigma_across <= 50.0))
    return "sigma_along and sigma_across must be 0..50 m";
  for (float v : c.cost)
    if (!(v >= 0.0f && v <= 100.0f)) return "class costs must be 0..100";
  if (!(c.unknown_cost >= 0.0f && c.unknown_cost <= 100.0f)) return "unknown_cost must be 0..100";
  if (!(c.along_prior >= 0.0 && c.along_prior <= 1000.0)) return "along_prior must be 0..1000 m (0: off)";
  if (!(c.corner_sigma >= 0.0 && c.corner_sigma <= 50.0)) return "corner_sigma must be 0..50 m (0: off)";
  if (!(c.corner_angle > 0.0 && c.corner_angle < 3.1416)) return "corner_angle must be in (0, pi) rad";
  if (!(c.corner_turn >= 0.0 && c.corner_turn <= 1.0)) return "corner_turn must be 0..1 rad (0: off)";
  if (!(c.separation >= 0.0 && c.separation <= 4.0)) return "separation must be 0..4 subgoal spacings (0: off)";
  if (!(c.resample_below >= 0.0 && c.resample_below <= 1.0)) return "resample_below must be 0..1";
  if (c.max_subgoals < 2 || c.max_subgoals > 10000000) return "max_subgoals must be 2..10000000";
  return {};
}

SubgoalAligner::SubgoalAligner(const AlignerConfig& config, const perception::TerrainMapShape& shape)
    : config_(config),
      k_(config.sequence),
      kk_(static_cast<std::size_t>(config.sequence)),
      n_(config.samples),
      resolution_(shape.resolution) {
  normal_.resize(kTable);
  tan_theta_.resize(kTable);
  turn_.resize(kTable);
  for (std::size_t i = 0; i < kTable; ++i) {
    const double z = normal_quantile((static_cast<double>(i) + 0.5) / static_cast<double>(kTable));
    normal_[i] = z;
    tan_theta_[i] = std::tan(config.sigma_theta * z);
    turn_[i] = {std::cos(config.corner_turn * z), std::sin(config.corner_turn * z)};
  }
  window_.resize(n_ * kk_);
  anchor_.resize(n_);
  log_alpha_.assign(n_, 0.0);
  weight_.assign(n_, 1.0 / static_cast<double>(n_));
  log_weight_.resize(n_);
  prior_.assign(n_, 0.0);
  extra_.resize(n_ * kExtra);
  anchor_tmp_.resize(n_);
  estimates_.resize(config.max_subgoals);
  estimated_.assign(config.max_subgoals, 0);
  box_capacity_ = static_cast<std::size_t>(shape.size_x + 1) * static_cast<std::size_t>(shape.size_y + 1);
  sat_.resize(box_capacity_);
  sat_known_.resize(box_capacity_);
  reset();
}

void SubgoalAligner::reset() noexcept {
  count_ = 0;
  drawn_ = 0;
  std::uint64_t s = config_.seed + 0x51ed2701ULL * ++resets_;
  for (auto& r : rng_) r = splitmix(s);
  std::fill(log_alpha_.begin(), log_alpha_.end(), 0.0);
  std::fill(weight_.begin(), weight_.end(), 1.0 / static_cast<double>(n_));
  std::fill(estimated_.begin(), estimated_.end(), std::uint8_t{0});
  counters_.last_neff = static_cast<double>(n_);
}

std::uint64_t SubgoalAligner::next_random() noexcept {  // xoshiro256**
  const std::uint64_t result = rotl(rng_[1] * 5, 7) * 9;
  const std::uint64_t t = rng_[1] << 17;
  rng_[2] ^= rng_[0];
  rng_[3] ^= rng_[1];
  rng_[1] ^= rng_[2];
  rng_[0] ^= rng_[3];
  rng_[2] ^= t;
  rng_[3] = rotl(rng_[3], 45);
  return result;
}

void SubgoalAligner::draw_window(std::span<const Vec2> raw, const RouteShape& shape) noexcept {
  const std::size_t begin = window_begin();
  const std::size_t len = count_ - begin;
  const std::size_t base = begin > 0 ? begin - 1 : 0;  // the anchor's subgoal (or subgoal 0)
  // The route near the window, pts[m] with its arc length: the shape's
  // vertices, or without one the raw subgoals from the one before the
  // anchor's to up to kAhead beyond the window. sa(g): raw subgoal g's arc.
  std::array<Vec2, kShapePoints> pts{};
  std::array<double, kShapePoints> arc{};
  std::size_t np = 0;
  const bool given = !shape.points.empty();
  const std::size_t first = base > 0 ? base - 1 : 0;
  if (given) {
    np = std::min({shape.points.size(), shape.arc.size(), kShapePoints});
    for (std::size_t m = 0; m < np; ++m) {
      pts[m] = shape.points[m];
      arc[m] = shape.arc[m];
    }
  } else {
    np = std::min({raw.size(), count_ + kAhead, first + kShapePoints}) - first;
    for (std::size_t m = 0; m < np; ++m) {
      pts[m] = raw[first + m];
      arc[m] = m > 0 ? arc[m - 1] + std::hypot(pts[m].x - pts[m - 1].x, pts[m].y - pts[m - 1].y) : 0.0;
    }
  }
  const auto sa = [&](std::size_t g) { return given ? shape.subgoal_arc[g] : arc[g - first]; };
  const double a_base = sa(base), a_new = sa(count_ - 1);
  const double spacing = count_ - 1 > base ? (a_new - a_base) / static_cast<double>(count_ - 1 - base) : 4.0;
  spacing_ = spacing;
  // The first corner at the anchor or in the window: a vertex of the route
  // (one up to a subgoal spacing beyond the window's newest subgoal
  // included) where it turns by at least corner_angle. Failing that, the
  // last such vertex up to kBehind spacings behind the anchor: a junction
  // mapped too early, whose mapped turn the anchor has already passed.
  std::size_t vertex = 0;  // pts index
  bool corner = false;
  Vec2 in{};
  const double cos_corner = std::cos(config_.corner_angle);
  const double behind_from = a_base - kBehind * spacing - 1e-9;
  for (std::size_t v = 1; v + 1 < np && config_.corner_sigma > 0.0; ++v) {
    if (arc[v] < behind_from || (given ? arc[v] >= a_new + spacing - 1e-9 : v + first > count_ - 1)) continue;
    const double dx = pts[v].x - pts[v - 1].x, dy = pts[v].y - pts[v - 1].y, d = std::hypot(dx, dy);
    const double ox = pts[v + 1].x - pts[v].x, oy = pts[v + 1].y - pts[v].y, od = std::hypot(ox, oy);
    if (d < 1e-9 || od < 1e-9 || (dx * ox + dy * oy) / (d * od) >= cos_corner) continue;
    vertex = v;
    in = {dx / d, dy / d};
    corner = true;
    if (arc[v] >= a_base - 1e-9) break;  // ahead of the anchor: this one
  }
  // Eq. 8.8: the street direction at g_0.
  Vec2 e0{1.0, 0.0};
  double along = std::max(config_.sigma_along, config_.sigma_across), across = along;
  if (begin == 0 && count_ >= 2) {
    const double dx = raw[1].x - raw[0].x, dy = raw[1].y - raw[0].y, d = std::hypot(dx, dy);
    if (d > 1e-9) {
      e0 = {dx / d, dy / d};
      along = config_.sigma_along;
      across = config_.sigma_across;
    }
  }
  // The route with the corner moved by s along the street before it: the
  // street before the corner ends s further on (s < 0: earlier), everything
  // after it moves by s * in (and turns about the corner), and each subgoal
  // keeps its arc length. A subgoal the map put on the stretch between the
  // real and the mapped junction so goes round the real corner instead of
  // beside it.
  const double av = arc[vertex];
  const auto route_at = [&](double b, std::size_t t) {  // the route at arc length b (t: a vertex at or before it)
    while (t + 2 < np && arc[t + 1] < b) ++t;
    const double seg = arc[t + 1] - arc[t];
    const double f = seg > 1e-9 ? (b - arc[t]) / seg : 0.0;
    return Vec2{pts[t].x + f * (pts[t + 1].x - pts[t].x), pts[t].y + f * (pts[t + 1].y - pts[t].y)};
  };
  double rc = 1.0, rs = 0.0;  // the sample's turn of the route after the corner
  const auto before_corner = [&](double a, double s) { return s >= 0.0 ? a <= av : a <= av + s; };
  const auto moved_at = [&](double a, double s) {
    if (before_corner(a, s)) return route_at(a, 0);
    if (s > 0.0 && a <= av + s) return Vec2{pts[vertex].x + (a - av) * in.x, pts[vertex].y + (a - av) * in.y};
    const Vec2 q = route_at(a - s, vertex);
    const double qx = q.x - pts[vertex].x, qy = q.y - pts[vertex].y;
    return Vec2{pts[vertex].x + s * in.x + rc * qx - rs * qy, pts[vertex].y + s * in.y + rs * qx + rc * qy};
  };
  const auto moved = [&](std::size_t g, double s) { return before_corner(sa(g), s) ? raw[g] : moved_at(sa(g), s); };
  const double s_min = -(av - a_base);  // the turn at the anchor at the earliest

  constexpr std::uint64_t kMask = kTable - 1;
  const double inv2s2 = config_.along_prior > 0.0 ? 0.5 / (config_.along_prior * config_.along_prior) : 0.0;
  double min_x = std::numeric_limits<double>::max(), min_y = min_x, max_x = -min_x, max_y = -min_x;
  // The steps of Eq. 8.6 (unit direction and length) between the window
  // subgoals of a route `hyp`, from the anchor's subgoal on: the raw route's,
  // or a corner sample's moved one.
  std::array<Vec2, 8> hyp{};
  std::array<Vec2, 8> sdir{};
  std::array<double, 8> sdist{};
  const auto steps_of = [&](Vec2 last) {
    for (std::size_t i = 0; i < len; ++i) {
      if (begin + i == 0) continue;
      const double dx = hyp[i].x - last.x, dy = hyp[i].y - last.y, d = std::hypot(dx, dy);
      sdist[i] = d;
      sdir[i] = d > 1e-9 ? Vec2{dx / d, dy / d} : Vec2{1.0, 0.0};
      last = hyp[i];
    }
  };
  for (std::size_t i = 0; i < len; ++i) hyp[i] = raw[begin + i];
  steps_of(raw[base]);
  // Route beyond the window to score (none past the route's end).
  const std::size_t beyond = given ? static_cast<std::size_t>(std::max(0.0, (arc[np - 1] - a_new) / spacing + 1e-6))
                                   : first + np - count_;
  const std::size_t extra = corner ? std::min(kExtra, beyond) : 0;
  double shift = 0.0;
  for (std::size_t j = 0; j < n_; ++j) {
    Vec2* w = &window_[j * kk_];
    Vec2 prev = anchor_[j];
    if (corner) {
      // This sample's corner shift and turn, and the steps of its moved route.
      const std::uint64_t rr = next_random();
      shift = config_.corner_sigma * normal_[rr & kMask];
      rc = turn_[(rr >> 12) & kMask].x;
      rs = turn_[(rr >> 12) & kMask].y;
      if (av < a_base && shift <= s_min) {
        // A mapped corner behind the anchor that stays behind it: the route
        // as mapped (the turn already taken).
        shift = 0.0;
        rc = 1.0;
        rs = 0.0;
      } else {
        shift = std::max(s_min, shift);
      }
      for (std::size_t i = 0; i < len; ++i) hyp[i] = moved(begin + i, shift);
      steps_of(moved(base, shift));
    }
    double a2 = 0.0;
    for (std::size_t i = 0; i < len; ++i) {
      const std::size_t g = begin + i;
      const std::uint64_t r = next_random();
      Vec2 p;
      if (g == 0) {
        const double a = along * normal_[r & kMask], c = across * normal_[(r >> 12) & kMask];
        p = {raw[0].x + a * e0.x - c * e0.y, raw[0].y + a * e0.y + c * e0.x};
      } else {
        // Eq. 8.6: (d + dd) along the step, (d + dd) tan(dth) across it.
        const double l = sdist[i] + config_.sigma_d * normal_[r & kMask];
        const double lt = l * tan_theta_[(r >> 12) & kMask];
        p = {prev.x + l * sdir[i].x - lt * sdir[i].y, prev.y + l * sdir[i].y + lt * sdir[i].x};
      }
      // The along-street prior: the offset from this sample's route along its street.
      const Vec2 t = (g == 0 && len > 1) ? sdir[1] : sdir[i];
      const double a = (p.x - hyp[i].x) * t.x + (p.y - hyp[i].y) * t.y;
      a2 += a * a;
      w[g % kk_] = p;
      prev = p;
      min_x = std::min(min_x, p.x);
      max_x = std::max(max_x, p.x);
      min_y = std::min(min_y, p.y);
      max_y = std::max(max_y, p.y);
    }
    prior_[j] = a2 * inv2s2;
    // The route beyond the window as this sample continues it: the raw
    // subgoals ahead, moved by its corner shift and by where its newest
    // subgoal lies. They are scored, not estimated: they tell the turns
    // apart that the window alone cannot (at a crossing both ways are trail).
    for (std::size_t e = 0; e < extra; ++e) {
      const double b = std::max(a_new, av + shift) + spacing * static_cast<double>(e + 1);
      const Vec2 h = moved_at(b, shift);
      const Vec2 q = {h.x + prev.x - hyp[len - 1].x, h.y + prev.y - hyp[len - 1].y};
      extra_[j * kExtra + e] = q;
      min_x = std::min(min_x, q.x);
      max_x = std::max(max_x, q.x);
      min_y = std::min(min_y, q.y);
      max_y = std::max(max_y, q.y);
    }
  }
  extra_count_ = extra;
  min_x_ = min_x;
  min_y_ = min_y;
  max_x_ = max_x;
  max_y_ = max_y;
  drawn_ = count_;
}

void SubgoalAligner::build_cost_table(const perception::TerrainClassMap& map) noexcept {
  const auto& grid = map.grid();
  const auto nb = static_cast<std::int32_t>(config_.neighbourhood);
  const CellIndex lo = grid.world_to_index(min_x_, min_y_);
  const CellIndex hi = grid.world_to_index(max_x_, max_y_);
  const CellIndex o = grid.origin();
  // The samples' box plus the neighbourhood, clipped to the map.
  const std::int32_t x0 = std::max(lo.x - nb, o.x), y0 = std::max(lo.y - nb, o.y);
  const std::int32_t x1 = std::min(hi.x + nb, o.x + grid.size_x() - 1), y1 = std::min(hi.y + nb, o.y + grid.size_y() - 1);
  box_x0_ = x0;
  box_y0_ = y0;
  box_w_ = std::max(0, x1 - x0 + 1);
  box_h_ = std::max(0, y1 - y0 + 1);
  if (box_w_ == 0 || box_h_ == 0) {
    counters_.cells_summed = 0;
    return;
  }
  const bool learnt = config_.cell_cost == AlignerConfig::CellCost::traversability;
  // sat_[(y + 1) * (w + 1) + (x + 1)] = sum of f^E over [0, x] x [0, y].
  const auto stride = static_cast<std::size_t>(box_w_ + 1);
  std::fill(sat_.begin(), sat_.begin() + static_cast<std::ptrdiff_t>(stride), 0.0);
  std::fill(sat_known_.begin(), sat_known_.begin() + static_cast<std::ptrdiff_t>(stride), 0u);
  for (std::int32_t y = 0; y < box_h_; ++y) {
    double row = 0.0;
    std::uint32_t row_known = 0;
    const std::size_t base = static_cast<std::size_t>(y + 1) * stride;
    sat_[base] = 0.0;
    sat_known_[base] = 0;
    for (std::int32_t x = 0; x < box_w_; ++x) {
      const perception::TerrainCell& c = grid.at({x0 + x, y0 + y});
      if (learnt) {
        if (c.traversable >= 0.0f) {
          row += static_cast<double>(perception::traversability_cost(c, config_.unknown_cost));
          ++row_known;
        }
      } else if (c.known) {
        row += static_cast<double>(perception::terrain_cost(c, config_.cost, config_.unknown_cost));
        ++row_known;
      }
      const std::size_t at = base + static_cast<std::size_t>(x) + 1;
      sat_[at] = sat_[at - stride] + row;
      sat_known_[at] = sat_known_[at - stride] + row_known;
    }
  }
  counters_.cells_summed = static_cast<std::uint64_t>(box_w_) * static_cast<std::uint64_t>(box_h_);
}

double SubgoalAligner::patch_cost(double x, double y, bool known_only) const noexcept {
  const auto nb = static_cast<std::int32_t>(config_.neighbourhood);
  const auto cx = static_cast<std::int32_t>(std::floor(x / resolution_)) - box_x0_;
  const auto cy = static_cast<std::int32_t>(std::floor(y / resolution_)) - box_y0_;
  const std::int32_t ax = std::max(cx - nb, 0), bx = std::min(cx + nb, box_w_ - 1);
  const std::int32_t ay = std::max(cy - nb, 0), by = std::min(cy + nb, box_h_ - 1);
  const double side = 2.0 * nb + 1.0;
  const double cells = side * side;
  double inside = 0.0, sum = 0.0;
  if (ax <= bx && ay <= by) {
    const auto stride = static_cast<std::size_t>(box_w_ + 1);
    const auto ux0 = static_cast<std::size_t>(ax), ux1 = static_cast<std::size_t>(bx) + 1;
    const auto uy0 = static_cast<std::size_t>(ay), uy1 = static_cast<std::size_t>(by) + 1;
    sum = sat_[uy1 * stride + ux1] - sat_[uy0 * stride + ux1] - sat_[uy1 * stride + ux0] + sat_[uy0 * stride + ux0];
    inside = static_cast<double>(sat_known_[uy1 * stride + ux1] - sat_known_[uy0 * stride + ux1] -
                                 sat_known_[uy1 * stride + ux0] + sat_known_[uy0 * stride + ux0]);
  }
  if (known_only) return inside > 0.0 ? sum / inside : static_cast<double>(config_.unknown_cost);
  // Unknown cells and cells beyond the map cost unknown_cost.
  return (sum + (cells - inside) * static_cast<double>(config_.unknown_cost)) / cells;
}

void SubgoalAligner::update(const perception::TerrainClassMap& map, std::span<const Vec2> raw,
                            const RouteShape& shape) noexcept {
  if (count_ == 0) return;
  draw_window(raw, shape);
  build_cost_table(map);
  const std::size_t begin = window_begin();
  // A sample's route in order: its anchor, its window, its route beyond.
  // Two points two or more steps apart must stay `separation` subgoal
  // spacings apart, or as far apart as the raw subgoals they stand for when
  // the map has those closer (a hairpin); the points beyond the window keep
  // the plain limit.
  constexpr std::size_t kRoute = 1 + static_cast<std::size_t>(kMaxSequence) + kExtra;
  const std::size_t first = begin > 0 ? begin - 1 : begin;
  const std::size_t route_n = (count_ - first) + extra_count_;
  std::array<double, kRoute * kRoute> limit2{};
  const double sep = config_.separation * spacing_;
  if (sep > 0.0) {
    for (std::size_t a = 0; a < route_n; ++a) {
      for (std::size_t b = a + 2; b < route_n; ++b) {
        double l = sep;
        if (first + b < count_ && first + b < raw.size()) {
          const Vec2 ra = raw[first + a], rb = raw[first + b];
          l = std::min(l, std::hypot(ra.x - rb.x, ra.y - rb.y));
        }
        limit2[a * kRoute + b] = l * l;
      }
    }
  }
  std::uint64_t doubled_back = 0;
  double best = -std::numeric_limits<double>::infinity();
  for (std::size_t j = 0; j < n_; ++j) {
    const Vec2* w = &window_[j * kk_];
    double c = 0.0;
    for (std::size_t g = begin; g < count_; ++g) {
      const Vec2& q = w[g % kk_];
      c += patch_cost(q.x, q.y, config_.known_cells_only);
    }
    for (std::size_t e = 0; e < extra_count_; ++e) c += patch_cost(extra_[j * kExtra + e].x, extra_[j * kExtra + e].y, true);
    double lw = log_alpha_[j] - config_.lambda * c - prior_[j];  // Eq. 8.11, 8.14 (lambda^K cancels)
    if (sep > 0.0 && route_n > 2) {
      std::array<Vec2, kRoute> route{};
      std::size_t m = 0;
      if (begin > 0) route[m++] = anchor_[j];
      for (std::size_t g = begin; g < count_; ++g) route[m++] = w[g % kk_];
      for (std::size_t e = 0; e < extra_count_; ++e) route[m++] = extra_[j * kExtra + e];
      bool back = false;
      for (std::size_t a = 0; a + 2 < m && !back; ++a) {
        for (std::size_t b = a + 2; b < m; ++b) {
          const double dx = route[a].x - route[b].x, dy = route[a].y - route[b].y;
          if (dx * dx + dy * dy < limit2[a * kRoute + b]) {
            back = true;
            break;
          }
        }
      }
      if (back) {
        lw -= kDoubledBack;
        ++doubled_back;
      }
    }
    log_weight_[j] = lw;
    best = std::max(best, lw);
  }
  counters_.last_doubled_back = doubled_back;
  double sum = 0.0;
  for (std::size_t j = 0; j < n_; ++j) {
    weight_[j] = std::exp(log_weight_[j] - best);
    sum += weight_[j];
  }
  double sq = 0.0;
  for (std::size_t j = 0; j < n_; ++j) {
    weight_[j] /= sum;
    sq += weight_[j] * weight_[j];
  }
  counters_.last_neff = 1.0 / sq;
  // The expectation of each window subgoal.
  for (std::size_t g = begin; g < count_; ++g) {
    double ex = 0.0, ey = 0.0;
    for (std::size_t j = 0; j < n_; ++j) {
      const Vec2& p = window_[j * kk_ + g % kk_];
      ex += weight_[j] * p.x;
      ey += weight_[j] * p.y;
    }
    estimates_[g] = {ex, ey};
    estimated_[g] = 1;
  }
  ++counters_.updates;
}

void SubgoalAligner::resample_anchors() noexcept {
  // Stochastic universal sampling: n equally spaced pointers, one random offset.
  const double step = 1.0 / static_cast<double>(n_);
  double u = step * static_cast<double>(next_random() >> 11) * 0x1.0p-53;
  double c = weight_[0];
  std::size_t i = 0;
  for (std::size_t j = 0; j < n_; ++j) {
    while (u > c && i + 1 < n_) c += weight_[++i];
    anchor_tmp_[j] = anchor_[i];
    u += step;
  }
  std::swap(anchor_, anchor_tmp_);
  std::fill(log_alpha_.begin(), log_alpha_.end(), 0.0);
  ++counters_.resamples;
}

bool SubgoalAligner::push(std::span<const Vec2> raw, const RouteShape& shape) noexcept {
  if (count_ >= config_.max_subgoals) return false;
  if (count_ >= kk_) {
    const std::size_t leaving = count_ - kk_;
    if (drawn_ != count_) {  // pushed without an update: draw the window now
      draw_window(raw, shape);
    }
    if (!estimated_[leaving]) {
      estimates_[leaving] = raw[leaving];
    }
    // The leaving subgoal's positions become the anchors, weighted by their sequences.
    double sq = 0.0;
    for (std::size_t j = 0; j < n_; ++j) {
      anchor_[j] = window_[j * kk_ + leaving % kk_];
      log_alpha_[j] = std::log(std::max(weight_[j], 1e-300));
      sq += weight_[j] * weight_[j];
    }
    if (1.0 / sq < config_.resample_below * static_cast<double>(n_)) resample_anchors();
  }
  ++count_;
  ++counters_.pushes;
  return true;
}

}  // namespace trailnav::subgoals
