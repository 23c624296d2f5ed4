// The subgoal aligner on terrain maps whose trail is known: subgoals mapped
// beside the trail are pulled onto it, a junction mapped too far along the
// road or too early is found where the map shows it, subgoals do not fall
// behind where the cells ahead are unseen, an empty map leaves the subgoals
// where they were, runs reproduce per seed, and updates never allocate.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <utility>
#include <vector>

#include "trailnav/navigation/subgoals/subgoal_aligner.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "terrain_paint.hpp"

namespace trailnav::subgoals {
namespace {

using perception::TerrainCell;
using perception::TerrainClass;
using perception::TerrainClassMap;

void paint(TerrainClassMap& map, double cx, double cy, const std::function<bool(double, double)>& on_street) {
  test::paint_terrain(map, cx, cy, on_street);
}

// Raw subgoals every 4 m from (x0, y0) along the polyline; aligns them one
// after the other as the robot would (push, then update), and returns the
// estimates of all of them.
std::vector<Vec2> run(SubgoalAligner& aligner, const TerrainClassMap& map, const std::vector<Vec2>& raw) {
  aligner.reset();
  for (std::size_t i = 0; i < raw.size(); ++i) {
    EXPECT_TRUE(aligner.push(raw));
    aligner.update(map, raw);
    aligner.update(map, raw);  // several updates per subgoal, as the map changes
  }
  std::vector<Vec2> out;
  for (std::size_t i = 0; i < raw.size(); ++i) out.push_back(aligner.estimate(i));
  return out;
}

std::vector<Vec2> straight(double y, int n, double x0 = 0.0) {
  std::vector<Vec2> v;
  for (int i = 0; i < n; ++i) v.push_back({x0 + 4.0 * i, y});
  return v;
}

// Aligns `raw` on a map of `roads` with the given corner spread and returns
// the largest `off` of the estimates from subgoal `first` on.
double worst_estimate(double corner_sigma, const std::function<bool(double, double)>& roads, const std::vector<Vec2>& raw,
                      std::size_t first, const std::function<double(const Vec2&)>& off) {
  AlignerConfig c;
  c.corner_sigma = corner_sigma;
  TerrainClassMap map;
  paint(map, 20.0, 10.0, roads);
  SubgoalAligner aligner(c, map.shape());
  const auto est = run(aligner, map, raw);
  double worst = 0.0;
  for (std::size_t i = first; i < est.size(); ++i) worst = std::max(worst, off(est[i]));
  return worst;
}

TEST(SubgoalAligner, ChecksItsConfiguration) {
  AlignerConfig c;
  EXPECT_EQ(check_aligner_config(c), "");
  c.samples = 60000;
  EXPECT_NE(check_aligner_config(c).find("samples"), std::string::npos);
  c = {};
  c.sequence = 0;
  EXPECT_NE(check_aligner_config(c).find("sequence"), std::string::npos);
  c = {};
  c.sigma_theta = 0.6;
  EXPECT_NE(check_aligner_config(c).find("sigma_theta"), std::string::npos);
  c = {};
  c.lambda = 0.0;
  EXPECT_NE(check_aligner_config(c).find("lambda"), std::string::npos);
  c = {};
  c.along_prior = -1.0;
  EXPECT_NE(check_aligner_config(c).find("along_prior"), std::string::npos);
  c = {};
  c.separation = 4.5;
  EXPECT_NE(check_aligner_config(c).find("separation"), std::string::npos);
  c = {};
  c.corner_angle = 0.0;
  EXPECT_NE(check_aligner_config(c).find("corner_angle"), std::string::npos);
  c = {};
  c.corner_turn = 1.5;
  EXPECT_NE(check_aligner_config(c).find("corner_turn"), std::string::npos);
}

TEST(SubgoalAligner, PullsSubgoalsMappedBesideTheTrailOntoIt) {
  TerrainClassMap map;
  // The true street: 3 m wide along y = 2.5; the map puts it along y = 0.
  paint(map, 25.0, 0.0, [](double, double y) { return std::abs(y - 2.5) < 1.5; });
  SubgoalAligner aligner({}, map.shape());
  const auto raw = straight(0.0, 14);
  const auto est = run(aligner, map, raw);
  double sq = 0.0;
  for (std::size_t i = 2; i < est.size(); ++i) sq += (est[i].y - 2.5) * (est[i].y - 2.5);
  const double rmse = std::sqrt(sq / static_cast<double>(est.size() - 2));
  EXPECT_LT(rmse, 0.35);  // raw: 2.5 m
  for (std::size_t i = 1; i < est.size(); ++i) EXPECT_NEAR(est[i].x - est[i - 1].x, 4.0, 1.0) << i;
  EXPECT_EQ(aligner.counters().pushes, 14u);
  EXPECT_GT(aligner.counters().resamples, 0u);
}

TEST(SubgoalAligner, EmptyMapLeavesSubgoalsAroundTheirMappedPlace) {
  TerrainClassMap map;  // nothing observed: every cell costs as `other`
  AlignerConfig c;
  c.samples = 5000;
  SubgoalAligner aligner(c, map.shape());
  const auto raw = straight(0.0, 10);
  const auto est = run(aligner, map, raw);
  for (std::size_t i = 0; i < est.size(); ++i) {
    EXPECT_NEAR(est[i].y, 0.0, 0.6) << i;
    EXPECT_NEAR(est[i].x, raw[i].x, 1.2) << i;
  }
}

TEST(SubgoalAligner, FindsAJunctionMappedTooFarAlong) {
  // True road: east along y = 0 to x = 20, then north along x = 20. The map
  // turns 6 m too late, at x = 26.
  TerrainClassMap map;
  paint(map, 20.0, 10.0, [](double x, double y) {
    return (std::abs(y) < 1.5 && x < 21.5) || (std::abs(x - 20.0) < 1.5 && y > -1.5);
  });
  std::vector<Vec2> raw = straight(0.0, 7);  // 0..24
  raw.push_back({26.0, 0.0});
  for (int i = 1; i <= 7; ++i) raw.push_back({26.0, 4.0 * i - 2.0});
  // Points every 4 m would be closer to the road's; the corner makes one step 2 m.
  SubgoalAligner aligner({}, map.shape());
  const auto est = run(aligner, map, raw);
  // After the corner, the subgoals run up the true road (x = 20), not the mapped one (x = 26).
  for (std::size_t i = 10; i < est.size(); ++i) EXPECT_NEAR(est[i].x, 20.0, 1.0) << i;
}

// The map the robot has when subgoal i joins: the street seen up to `seen`
// metres ahead of the subgoal before it, nothing beyond.
void paint_seen(TerrainClassMap& map, double cx, double cy, double seen_x, const std::function<bool(double, double)>& on_street) {
  paint(map, cx, cy, on_street);
  auto& grid = map.grid();
  const CellIndex o = grid.origin();
  for (std::int32_t y = o.y; y < o.y + grid.size_y(); ++y)
    for (std::int32_t x = o.x; x < o.x + grid.size_x(); ++x)
      if (grid.cell_center({x, y}).x > seen_x) grid.at({x, y}) = TerrainCell{};
}

// Along a straight street whose far end the lidar has not seen yet, the
// subgoals stay where the map puts them along it: the along-street prior
// keeps the sequences that stop short of the unseen cells from winning
// every update (without it, the thesis' model, they fall behind).
TEST(SubgoalAligner, KeepsSubgoalsAlongTheStreetWhenTheCellsAheadAreUnseen) {
  const auto street = [](double, double y) { return std::abs(y) < 1.5; };
  const auto lag_of_last = [&](double along_prior) {
    AlignerConfig c;
    c.along_prior = along_prior;
    TerrainClassMap map;
    SubgoalAligner aligner(c, map.shape());
    const auto raw = straight(0.0, 16);
    double lag = 0.0;
    for (std::size_t i = 0; i < raw.size(); ++i) {
      EXPECT_TRUE(aligner.push(raw));
      // The robot is 12 m behind the newest subgoal and has seen 15 m ahead.
      const double robot = std::max(0.0, raw[i].x - 12.0);
      paint_seen(map, robot, 0.0, robot + 15.0, street);
      for (int k = 0; k < 3; ++k) aligner.update(map, raw);
      if (i >= 4) lag = std::max(lag, raw[i - 4].x - aligner.estimate(i - 4).x);
    }
    return lag;
  };
  const double with_prior = lag_of_last(6.0), thesis = lag_of_last(0.0);
  std::printf("largest lag behind the raw subgoal: %.2f m with the prior, %.2f m without\n", with_prior, thesis);
  EXPECT_LT(with_prior, 1.0);
  EXPECT_GT(thesis, with_prior + 0.5);
}

// A junction node mapped 8 m before the real junction: the raw route turns
// north at x = 20, the road at x = 28. The corner shift moves the turn;
// Eq. 8.6's small steps alone leave the subgoals beside the road.
TEST(SubgoalAligner, MovesATurnMappedTooEarlyToWhereTheMapShowsIt) {
  const double jx = 28.0;
  const auto road = [&](double x, double y) { return (std::abs(y) < 1.5 && x < jx + 1.5) || (std::abs(x - jx) < 1.5 && y > -1.5); };
  std::vector<Vec2> raw = straight(0.0, 6);  // 0..20
  for (int i = 1; i <= 8; ++i) raw.push_back({20.0, 4.0 * i});
  const auto error_after_turn = [&](double corner_sigma) {
    return worst_estimate(corner_sigma, road, raw, 8, [&](const Vec2& e) { return std::abs(e.x - jx); });
  };
  const double shifted = error_after_turn(3.0), thesis = error_after_turn(0.0);
  std::printf("farthest subgoal from the road after the turn: %.2f m with the corner shift, %.2f m without\n", shifted, thesis);
  EXPECT_LT(shifted, 1.0);
  EXPECT_GT(thesis, shifted);
}

// An X crossing whose node is mapped 6 m too far along: the road goes on
// straight past the real junction, so the subgoals the map puts on the
// stretch between the real and the mapped node lie on a road too, only not
// on the route. Moving the corner with the subgoals' arc lengths kept, and
// scoring the route beyond the window, takes them round the real corner; the
// thesis' model leaves them on the straight-on road.
TEST(SubgoalAligner, TakesTheRealTurnAtACrossingMappedTooFarAlong) {
  const double jx = 20.0;
  const auto roads = [&](double x, double y) { return std::abs(y) < 1.5 || std::abs(x - jx) < 1.5; };
  std::vector<Vec2> raw = straight(0.0, 7);  // 0..24
  raw.push_back({26.0, 0.0});
  for (int i = 1; i <= 7; ++i) raw.push_back({26.0, 4.0 * i - 2.0});
  // Distance to the route: east along y = 0 to the junction, then north.
  const auto off_route = [&](const Vec2& p) {
    const double east = p.x <= jx ? std::abs(p.y) : std::hypot(p.x - jx, p.y);
    const double north = p.y >= 0.0 ? std::abs(p.x - jx) : std::hypot(p.x - jx, p.y);
    return std::min(east, north);
  };
  const auto worst = [&](double corner_sigma) { return worst_estimate(corner_sigma, roads, raw, 0, off_route); };
  const double moved = worst(AlignerConfig{}.corner_sigma), thesis = worst(0.0);
  std::printf("farthest subgoal from the route: %.2f m with the corner model, %.2f m without\n", moved, thesis);
  EXPECT_LT(moved, 2.0);  // the junction criterion of eval-subgoals: within 0.5 m of the 3 m road's edge
  EXPECT_GT(thesis, 4.0);
}

// A route does not come back to where it was. Junction (a) of the
// `junctions` drives: an X crossing at x = 20 whose node is mapped 7 m too
// far along the straight-on road, so the mapped way runs on past the
// junction and comes back askew to the branch. Samples that fit that spike
// by running out along the straight-on road and back along it (on road all
// the way) are weighted out; none that counts comes closer than a subgoal
// spacing (or than the map's own subgoals) to where it was two or more steps
// before. On a straight road and round a right-angled corner the rule
// weighs out (next to) nothing.
TEST(SubgoalAligner, WeighsOutSequencesThatDoubleBack) {
  const double jx = 20.0;
  const auto roads = [&](double x, double y) { return std::abs(y) < 1.5 || (std::abs(x - jx) < 1.5 && y > -1.5); };
  // Raw subgoals every 4 m along a polyline, with its vertices as the route shape.
  const auto along = [](const std::vector<Vec2>& way, std::vector<Vec2>& raw, std::vector<double>& raw_arc,
                        std::vector<double>& way_arc) {
    way_arc = {0.0};
    for (std::size_t i = 1; i < way.size(); ++i)
      way_arc.push_back(way_arc.back() + std::hypot(way[i].x - way[i - 1].x, way[i].y - way[i - 1].y));
    for (double a = 0.0; a <= way_arc.back(); a += 4.0) {
      std::size_t v = 0;
      while (v + 2 < way.size() && way_arc[v + 1] < a) ++v;
      const double f = (a - way_arc[v]) / (way_arc[v + 1] - way_arc[v]);
      raw.push_back({way[v].x + f * (way[v + 1].x - way[v].x), way[v].y + f * (way[v + 1].y - way[v].y)});
      raw_arc.push_back(a);
    }
  };
  TerrainClassMap map;
  paint(map, 20.0, 10.0, roads);
  struct Outcome {
    std::uint64_t doubled_back = 0;  // samples weighted out, summed over the updates
    std::uint64_t samples = 0;       // samples scored, summed
    bool kept_ones_keep_apart = true;
  };
  const auto run_on = [&](const std::vector<Vec2>& way, double separation) {
    std::vector<Vec2> raw;
    std::vector<double> raw_arc, way_arc;
    along(way, raw, raw_arc, way_arc);
    AlignerConfig c;
    c.separation = separation;
    SubgoalAligner aligner(c, map.shape());
    const RouteShape shape{way, way_arc, raw_arc};
    Outcome o;
    for (std::size_t i = 0; i < raw.size(); ++i) {
      EXPECT_TRUE(aligner.push(raw, shape));
      aligner.update(map, raw, shape);
      o.doubled_back += aligner.counters().last_doubled_back;
      o.samples += c.samples;
      const std::size_t begin = aligner.window_begin();
      for (std::size_t j = 0; j < c.samples; ++j) {
        if (aligner.weight(j) < 1e-9) continue;
        for (std::size_t a = begin; a < aligner.count(); ++a) {
          for (std::size_t b = a + 2; b < aligner.count(); ++b) {
            const Vec2 p = aligner.sample(j, a), q = aligner.sample(j, b);
            const double limit = std::min(4.0 * separation, std::hypot(raw[a].x - raw[b].x, raw[a].y - raw[b].y));
            if (std::hypot(p.x - q.x, p.y - q.y) < limit - 1e-9) o.kept_ones_keep_apart = false;
          }
        }
      }
    }
    return o;
  };
  const std::vector<Vec2> spike{{0.0, 0.0}, {27.0, 1.0}, {21.0, 13.0}, {21.0, 36.0}};
  const Outcome on = run_on(spike, AlignerConfig{}.separation);
  const Outcome off = run_on(spike, 0.0);
  EXPECT_GT(on.doubled_back, on.samples / 100);  // the spike invites them
  EXPECT_TRUE(on.kept_ones_keep_apart);
  EXPECT_EQ(off.doubled_back, 0u);
  // The real route, mapped where it is: east, then north at the junction.
  const Outcome corner = run_on({{0.0, 0.0}, {jx, 0.0}, {jx, 36.0}}, AlignerConfig{}.separation);
  EXPECT_LT(corner.doubled_back, corner.samples / 50);  // noise now and then: 5.7 m nominal against 4
  EXPECT_TRUE(corner.kept_ones_keep_apart);
  const Outcome straight_on = run_on({{0.0, 0.0}, {40.0, 0.0}}, AlignerConfig{}.separation);
  EXPECT_EQ(straight_on.doubled_back, 0u);
  std::printf("samples weighted out for doubling back: %.2f %% on the spike, %.3f %% round the corner, %.3f %% straight on\n",
              100.0 * static_cast<double>(on.doubled_back) / static_cast<double>(on.samples),
              100.0 * static_cast<double>(corner.doubled_back) / static_cast<double>(corner.samples),
              100.0 * static_cast<double>(straight_on.doubled_back) / static_cast<double>(straight_on.samples));
}

// An X crossing at x = jx of a road along y = 0 and one along x = jx, the
// route east then north; the mapped way turns north at x = mapped (to y =
// way_end) and the raw subgoals lie every 4 m along it up to arc `last`; the
// aligner is given the way's vertices. Returns the farthest estimate from the
// route with the default corner model and with the thesis' model.
std::pair<double, double> farthest_at_mapped_crossing(double jx, double mapped, double way_end, double last) {
  const auto roads = [&](double x, double y) { return std::abs(y) < 1.5 || std::abs(x - jx) < 1.5; };
  const std::vector<Vec2> way{{0.0, 0.0}, {mapped, 0.0}, {mapped, way_end}};
  const std::vector<double> way_arc{0.0, mapped, mapped + way_end};
  std::vector<Vec2> raw;
  std::vector<double> raw_arc;
  for (double a = 0.0; a <= last; a += 4.0) {
    raw.push_back(a <= mapped ? Vec2{a, 0.0} : Vec2{mapped, a - mapped});
    raw_arc.push_back(a);
  }
  const auto off_route = [&](const Vec2& p) {
    const double east = p.x <= jx ? std::abs(p.y) : std::hypot(p.x - jx, p.y);
    const double north = p.y >= 0.0 ? std::abs(p.x - jx) : std::hypot(p.x - jx, p.y);
    return std::min(east, north);
  };
  TerrainClassMap map;
  paint(map, 20.0, 10.0, roads);
  const auto worst = [&](double corner_sigma) {
    AlignerConfig c;
    c.corner_sigma = corner_sigma;
    SubgoalAligner aligner(c, map.shape());
    const RouteShape shape{way, way_arc, raw_arc};
    for (std::size_t i = 0; i < raw.size(); ++i) {
      EXPECT_TRUE(aligner.push(raw, shape));
      aligner.update(map, raw, shape);
      aligner.update(map, raw, shape);
    }
    double w = 0.0;
    for (std::size_t i = 0; i < raw.size(); ++i) w = std::max(w, off_route(aligner.estimate(i)));
    return w;
  };
  return {worst(AlignerConfig{}.corner_sigma), worst(0.0)};
}

// The same crossing with subgoals every 4 m along the mapped way, which cut
// its corner: given the way's own vertices (the navigator passes them), the
// corner model turns where the way turns and the subgoals still go round the
// real corner.
TEST(SubgoalAligner, TakesTheRealTurnAtTheMappedWaysOwnVertex) {
  const auto [moved, thesis] = farthest_at_mapped_crossing(20.0, 26.0, 40.0, 56.0);
  std::printf("farthest subgoal from the route: %.2f m with the corner model at the way's vertex, %.2f m without\n", moved, thesis);
  EXPECT_LT(moved, 2.0);
  EXPECT_GT(thesis, 4.0);
}

// An X crossing mapped 8 m too early, its mapped turn between two
// subgoals: by the time the subgoals after the turn join the window, the
// turn lies behind their anchor. The corner is still moved forward past the
// anchor to the crossing the map shows. (Before, corners were only looked
// for from the anchor on: 4.13 m here.)
TEST(SubgoalAligner, MovesATurnMappedTooEarlyFromBehindTheAnchor) {
  const auto [moved, thesis] = farthest_at_mapped_crossing(26.0, 18.0, 50.0, 60.0);
  std::printf("farthest subgoal from the route: %.2f m with the corner moved from behind the anchor, %.2f m without\n", moved,
              thesis);
  EXPECT_LT(moved, 2.0);
  EXPECT_GT(thesis, 4.0);
}

TEST(SubgoalAligner, ReproducesPerSeed) {
  TerrainClassMap map;
  paint(map, 25.0, 0.0, [](double, double y) { return std::abs(y - 1.5) < 1.5; });
  AlignerConfig c;
  SubgoalAligner a(c, map.shape()), b(c, map.shape());
  c.seed = 2;
  SubgoalAligner other(c, map.shape());
  const auto raw = straight(0.0, 8);
  const auto ea = run(a, map, raw), eb = run(b, map, raw), eo = run(other, map, raw);
  bool differs = false;
  for (std::size_t i = 0; i < raw.size(); ++i) {
    EXPECT_EQ(ea[i].x, eb[i].x);
    EXPECT_EQ(ea[i].y, eb[i].y);
    differs = differs || ea[i].x != eo[i].x;
  }
  EXPECT_TRUE(differs);
}

TEST(SubgoalAligner, UpdatesAndPushesNeverAllocate) {
  ASSERT_TRUE(alloc_guard::hook_installed());
  TerrainClassMap map;
  paint(map, 25.0, 0.0, [](double, double y) { return std::abs(y - 1.0) < 1.5; });
  AlignerConfig c;
  c.samples = 2000;
  c.sequence = 6;
  SubgoalAligner aligner(c, map.shape());
  const auto raw = straight(0.0, 20);
  alloc_guard::set_fatal(false);
  alloc_guard::reset_counters();
  alloc_guard::mark_realtime_thread("aligner-test");
  ASSERT_TRUE(alloc_guard::arm());
  aligner.reset();
  for (std::size_t i = 0; i < raw.size(); ++i) {
    aligner.push(raw);
    if (i % 3 != 1) aligner.update(map, raw);  // some pushes without an update
  }
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  EXPECT_GT(aligner.counters().updates, 10u);
}

}  // namespace
}  // namespace trailnav::subgoals
