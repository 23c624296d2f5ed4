// Subgoal alignment (thesis §8.2-8.3): moves the subgoals planned on
// OpenStreetMap onto the trail the terrain-class map shows, by sequential
// Monte-Carlo sampling over sequences of the K most recent subgoals.
//
// The subgoals arrive in the local odometry frame (their UTM positions
// transformed through the pose estimate), g^L_0..g^L_n. Between consecutive
// ones the relative step u_k = (theta_k, d_k) is taken from those raw
// positions. A sample j holds a sequence hypothesis G_j: positions for the
// window of the K newest subgoals, drawn one after another from the process
// model of Eq. 8.6,
//
//   g_k = g_{k-1} + (d_k + dd) / cos(dth) * (cos(theta_k + dth), sin(theta_k + dth)),
//
// with (dd, dth) ~ N(0, diag(sigma_d^2, sigma_theta^2)) (Eq. 8.7); that is a
// step of d_k + dd along theta_k and (d_k + dd) tan(dth) across it, so the
// spread is perpendicular to the street (Fig. 8.3). The first subgoal is
// drawn from N(g^L_0, Sigma_0), Sigma_0 rotated to the street direction
// (Eq. 8.8); later windows start from the sample's anchor, its position of
// the subgoal that last left the window.
//
// Weights (Eq. 8.9-8.11, 8.14): the cost of a cell is the expected class
// cost f^E(C) = sum_t f(t) P(t|C) (unknown cells: `unknown_cost`); a subgoal's
// cost f^N(g) is the mean over the (2N+1)^2 cells around it; its likelihood
// lambda exp(-lambda f^N(g)); a sequence's weight the anchor's weight times
// the product over the window (times the along-street prior, see
// AlignerConfig::along_prior, and nearly zero for a route doubling back on
// itself, AlignerConfig::separation). The estimate of each window subgoal is the
// weighted mean (the expectation).
//
// Each update() re-draws every window from its anchor against the current
// map, so the window always sees the newest terrain. When a new subgoal is
// pushed, the oldest leaves the window: its estimate is frozen, every
// sample's position of it becomes the sample's anchor, weighted by the
// sequence's weight, and when the effective sample size 1 / sum w^2 falls
// below half the samples the anchors are resampled by stochastic universal
// sampling (Baker). Windows are thus re-proposed, anchors carry the history.
//
// Costs: a summed-area table of f^E over the box the samples cover makes
// f^N four reads. The Gaussian draws come from inverse-CDF tables built at
// construction (the angle table holds tan(dth) directly), so a sample step
// needs no transcendental function. Everything is allocated by the
// constructor; update() and push() never allocate. Deterministic for a seed.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "trailnav/perception/terrain_class_map.hpp"

namespace trailnav::subgoals {

struct Vec2 {
  double x = 0.0, y = 0.0;
};

inline constexpr int kMaxSequence = 8;  // longest sequence K (AlignerConfig::sequence)

struct AlignerConfig {
  std::size_t samples = 1000;        // 1 .. 50000
  int sequence = 4;                  // K, subgoals sampled together, 1 .. kMaxSequence
  int neighbourhood = 2;             // N: (2N+1)^2 cells per subgoal
  double lambda = 4.0;               // Eq. 8.11
  double sigma_d = 0.5;              // m, Eq. 8.7
  double sigma_theta = 0.3;          // rad, Eq. 8.7 (at most 0.4)
  double sigma_along = 1.5;          // m, Sigma_0 along the street (Eq. 8.8)
  double sigma_across = 4.0;         // m, Sigma_0 across it
  std::array<float, perception::kTerrainClasses> cost{0.1f, 0.2f, 0.4f, 0.8f, 1.0f};  // §8.4.1
  float unknown_cost = 1.0f;         // cells without observations: as `other`
  // What a cell costs: its class distribution weighted by `cost` (§8.1.2),
  // or 1 − P(trav) of the robot's learnt traversability layer (thesis ch. 6,
  // TerrainCell::traversable; cells without its evidence are unknown).
  enum class CellCost : std::uint8_t { classes, traversability };
  CellCost cell_cost = CellCost::classes;
  // true: a patch's cost is the mean over its known cells (unknown_cost only
  // when none is known), so gaps between lidar rings ahead do not pull the
  // subgoals back towards the robot; false: unknown cells count as
  // unknown_cost (the thesis' §8.4.1 reading).
  bool known_cells_only = false;
  // Beyond the thesis (both 0 give its model exactly):
  // along_prior: sigma of a Gaussian prior on each window subgoal's offset
  // from its raw position along the raw street direction (the thesis' own
  // assumption that OSM errs mainly across the street). Without it, the
  // sequences that end short of the unseen cells ahead win every update and
  // the subgoals drift metres behind the raw ones, so they turn early.
  double along_prior = 6.0;          // m, 0: off
  // corner_sigma: where the route turns by at least corner_angle (at the
  // anchor, in the window or at the step just after it), each sample moves
  // that corner by s ~ N(0, corner_sigma^2) along the street before it: the
  // street before ends s later (s < 0: earlier, at the anchor at the
  // earliest), the route after it moves by s, and the subgoals keep their arc
  // lengths, so those the map put between the real and the mapped junction
  // go round the real corner. The corner is a vertex of the route's own
  // shape (RouteShape) where one is given. Each sample also turns the route
  // after the corner about it by phi ~ N(0, corner_turn^2): a junction node
  // mapped metres off drags the way leaving it askew. Such a sample's route
  // beyond the window is scored too (kExtra points a subgoal spacing apart,
  // after its corner if that lies beyond the window; a point's cost is the
  // mean over the known cells of its patch, unknown_cost if none is known):
  // at a crossing the window alone sees trail either way. Eq. 8.6's small
  // step noise cannot move a turn by metres.
  double corner_sigma = 12.0;        // m, 0: off
  double corner_angle = 0.45;        // rad
  double corner_turn = 0.3;          // rad, 0: the route after a corner keeps its direction
  // separation: a route does not come back to where it was. A sample whose
  // subgoals (its anchor, its window and its route scored beyond the window)
  // come closer than separation x the subgoal spacing to one two or more
  // steps before them, and closer than the map's own subgoals are to each
  // other, is a route doubling back on itself: its weight is multiplied by
  // exp(-kDoubledBack). Where a junction node is mapped metres too far along
  // a crossing road, the mapped way runs past the junction and back; a
  // sequence out along the straight-on road and back on it fits that spike
  // on trail all the way, and without this it outweighs the real turn.
  double separation = 1.0;           // x the subgoal spacing, 0: off
  double resample_below = 0.5;       // resample when n_eff < this x samples
  std::size_t max_subgoals = 65536;  // longest route, in subgoals
  std::uint64_t seed = 1;
};

// Empty when the configuration is usable, else what is wrong.
std::string check_aligner_config(const AlignerConfig& config);

struct AlignerCounters {
  std::uint64_t updates = 0;
  std::uint64_t pushes = 0;
  std::uint64_t resamples = 0;
  double last_neff = 0.0;           // effective sample size after the last update
  std::uint64_t last_doubled_back = 0;  // samples of the last update whose route came back on itself
  std::uint64_t cells_summed = 0;   // cells of the last update's cost table
};

// The route's shape near the aligner's window, for the corner model: its
// vertices in the odometry frame with their arc lengths along the route, and
// the arc length of each raw subgoal (indexed as `raw`). From the vertex
// before the anchor's subgoal to some way beyond the window; at most
// SubgoalAligner::kShapePoints vertices are read. Empty: the raw subgoals
// themselves are the route's shape (its corners cut by the subgoal spacing).
struct RouteShape {
  std::span<const Vec2> points;
  std::span<const double> arc;
  std::span<const double> subgoal_arc;
};

class SubgoalAligner {
 public:
  static constexpr std::size_t kShapePoints = 64;  // route vertices the corner model reads
  static constexpr std::size_t kAhead = 4;  // route subgoals beyond the window the corner model reads
  static constexpr double kDoubledBack = 1000.0;  // -log weight factor of a route coming back on itself
  static constexpr std::size_t kExtra = 2;  // of those, scored with a corner window
  // How many subgoal spacings behind the anchor a mapped corner may lie and
  // still be moved forward past it (a junction mapped too early).
  static constexpr double kBehind = 1.0;

  // Allocates the samples, tables and the cost box for `map_shape`.
  // Precondition: check_aligner_config(config) is empty.
  SubgoalAligner(const AlignerConfig& config, const perception::TerrainMapShape& map_shape);

  const AlignerConfig& config() const noexcept { return config_; }

  // Forgets every subgoal (a new route). Re-seeds the generator with
  // `seed` + the number of resets, so a run is reproducible.
  void reset() noexcept;
  // Appends the next subgoal; false beyond max_subgoals. `raw` as for
  // update() (it is read only when subgoals were pushed without an update
  // in between, to draw the one leaving the window).
  bool push(std::span<const Vec2> raw, const RouteShape& shape = {}) noexcept;
  std::size_t count() const noexcept { return count_; }
  // First subgoal in the window.
  std::size_t window_begin() const noexcept { return count_ > static_cast<std::size_t>(k_) ? count_ - static_cast<std::size_t>(k_) : 0; }

  // Re-samples the window against `map`. `raw` holds the raw local positions
  // of subgoals 0..count()-1 (only window_begin()-2 .. count()-1 are read),
  // and may go on with the route's next subgoals: up to kAhead of them shape
  // the corner model (see AlignerConfig::corner_sigma).
  void update(const perception::TerrainClassMap& map, std::span<const Vec2> raw, const RouteShape& shape = {}) noexcept;

  // The corrected position of subgoal i < count(): the window's current
  // estimate, or the estimate frozen when it left the window. Before the
  // first update of a subgoal, its raw position.
  Vec2 estimate(std::size_t i) const noexcept { return estimates_[i]; }
  bool estimated(std::size_t i) const noexcept { return estimated_[i] != 0; }

  const AlignerCounters& counters() const noexcept { return counters_; }
  // Sample j's position of window subgoal i (for plots and tests).
  Vec2 sample(std::size_t j, std::size_t i) const noexcept { return window_[j * kk_ + i % kk_]; }
  double weight(std::size_t j) const noexcept { return weight_[j]; }

 private:
  std::uint64_t next_random() noexcept;
  void draw_window(std::span<const Vec2> raw, const RouteShape& shape) noexcept;
  void build_cost_table(const perception::TerrainClassMap& map) noexcept;
  double patch_cost(double x, double y, bool known_only) const noexcept;
  void resample_anchors() noexcept;

  AlignerConfig config_;
  int k_;
  std::size_t kk_;
  std::size_t n_;
  double resolution_;
  std::size_t count_ = 0;
  std::size_t drawn_ = 0;  // count() at the last draw
  std::uint64_t resets_ = 0;
  std::array<std::uint64_t, 4> rng_{};

  static constexpr std::size_t kTable = 4096;
  std::vector<double> normal_;    // standard normal quantiles
  std::vector<double> tan_theta_;  // tan(sigma_theta * quantile)
  std::vector<Vec2> turn_;         // (cos, sin) of corner_turn * quantile

  std::vector<Vec2> window_;     // n x K ring, slot = subgoal % K
  std::vector<Vec2> anchor_;     // n
  std::vector<double> log_alpha_;  // n, anchors' log weights
  std::vector<double> weight_;   // n, normalised
  std::vector<double> log_weight_;  // n, log alpha - lambda * sum f^N over the window
  std::vector<Vec2> extra_;      // n x kExtra, the route ahead of each sample's window
  std::size_t extra_count_ = 0;
  std::vector<double> prior_;    // n, the along-street prior's -log factor of the drawn window
  std::vector<Vec2> anchor_tmp_;
  std::vector<Vec2> estimates_;  // max_subgoals
  std::vector<std::uint8_t> estimated_;

  // Summed-area table of f^E over a box of world cells.
  std::vector<double> sat_;
  std::vector<std::uint32_t> sat_known_;  // the same for the count of known cells
  std::int32_t box_x0_ = 0, box_y0_ = 0, box_w_ = 0, box_h_ = 0;
  std::size_t box_capacity_ = 0;
  double min_x_ = 0, min_y_ = 0, max_x_ = 0, max_y_ = 0;
  double spacing_ = 4.0;  // the raw subgoals' spacing at the last draw

  AlignerCounters counters_;
};

}  // namespace trailnav::subgoals
