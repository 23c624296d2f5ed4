#include "trailnav/navigation/navigator/navigation_config.hpp"

#include <filesystem>

namespace trailnav::nav {

NavigationSection parse_navigation_section(const ConfigNode& n) {
  NavigationSection s;
  const std::string osm = n.string("osm");
  const std::filesystem::path p(osm);
  s.osm = p.is_absolute() || n.file().empty() ? osm : (std::filesystem::path(n.file()).parent_path() / p).lexically_normal().string();
  if (!std::filesystem::exists(s.osm)) n.fail("osm", "no such file: " + s.osm);
  NavigatorConfig& c = s.navigator;
  // Optional: without it trailnavd waits, idle, for a goal over DDS.
  if (n.has("goal")) {
    const auto goal = n.number_list("goal", -180.0, 180.0);
    if (goal.size() != 2 || std::abs(goal[0]) > 84.0) n.fail("goal", "needs [latitude, longitude] in degrees (latitude within +-84)");
    c.goal_lat = goal[0];
    c.goal_lon = goal[1];
  }
  if (n.has("highways")) {
    s.profile.highways = n.string_list("highways");
    if (s.profile.highways.empty()) n.fail("highways", "names no highway type: the robot could drive nowhere");
  }
  s.profile.respect_oneway = !n.boolean("ignore_oneway", false);
  c.spacing = n.number("spacing", 0.5, 100.0, c.spacing);
  c.reach = n.number("reach", 0.05, 100.0, c.reach);
  c.lookahead = n.number("lookahead", 1.0, 500.0, c.lookahead);
  c.goal_tolerance = n.number("goal_tolerance", 0.1, 100.0, c.goal_tolerance);
  c.max_snap = n.number("max_snap", 1.0, 100000.0, c.max_snap);
  c.leave_distance = n.number("leave_distance", 1.0, 10000.0, c.leave_distance);
  c.leave_time = n.number("leave_time_s", 0.0, 3600.0, c.leave_time);
  c.replan_interval = n.number("replan_interval_s", 0.0, 3600.0, c.replan_interval);
  c.max_position_sigma = n.number("max_position_sigma", 0.1, 10000.0, c.max_position_sigma);
  c.path_poses = static_cast<std::size_t>(n.integer("path_poses", 1, 100000, static_cast<std::int64_t>(c.path_poses)));
  if (auto a = n.optional_map("aligner")) {
    subgoals::AlignerConfig& ac = c.aligner;
    ac.samples = static_cast<std::size_t>(a->integer("samples", 1, 50000, static_cast<std::int64_t>(ac.samples)));
    ac.sequence = static_cast<int>(a->integer("sequence", 1, subgoals::kMaxSequence, ac.sequence));
    ac.neighbourhood = static_cast<int>(a->integer("neighbourhood", 0, 10, ac.neighbourhood));
    ac.lambda = a->number("lambda", 0.0, 100.0, ac.lambda);
    ac.sigma_d = a->number("sigma_d", 0.0, 10.0, ac.sigma_d);
    ac.sigma_theta = a->number("sigma_theta", 0.0, 0.4, ac.sigma_theta);
    ac.sigma_along = a->number("sigma_along", 0.0, 100.0, ac.sigma_along);
    ac.sigma_across = a->number("sigma_across", 0.0, 100.0, ac.sigma_across);
    ac.along_prior = a->number("along_prior", 0.0, 1000.0, ac.along_prior);
    ac.corner_sigma = a->number("corner_sigma", 0.0, 50.0, ac.corner_sigma);
    ac.corner_turn = a->number("corner_turn", 0.0, 1.0, ac.corner_turn);
    ac.corner_angle = a->number("corner_angle", 0.01, 3.14, ac.corner_angle);
    ac.separation = a->number("separation", 0.0, 4.0, ac.separation);
    ac.known_cells_only = a->choice("unknown_cells", {"other", "known-only"}, "other") == "known-only";
    ac.cell_cost = a->choice("cell_cost", {"classes", "traversability"}, "classes") == "traversability"
                       ? subgoals::AlignerConfig::CellCost::traversability
                       : subgoals::AlignerConfig::CellCost::classes;
    ac.resample_below = a->number("resample_below", 0.0, 1.0, ac.resample_below);
    ac.seed = static_cast<std::uint64_t>(a->integer("seed", 0, std::numeric_limits<std::int64_t>::max(), 1));
    a->reject_unknown_keys();
  }
  if (std::string problem = check_navigator_config(c); !problem.empty()) n.fail("", problem);
  n.reject_unknown_keys();
  return s;
}

}  // namespace trailnav::nav
