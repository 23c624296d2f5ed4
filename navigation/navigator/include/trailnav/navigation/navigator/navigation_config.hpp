// The `navigation:` section of a robot config (docs/trailnavd.md,
// docs/navigation.md): the OpenStreetMap file and routing profile, the goal,
// the navigator's distances and the aligner's parameters. The class costs
// come from the terrain section (the cost layer of §8.1.2).
#pragma once

#include <string>

#include "trailnav/navigation/navigator/navigator.hpp"
#include "trailnav/navigation/osm/road_graph.hpp"
#include "trailnav/runtime/config.hpp"

namespace trailnav::nav {

struct NavigationSection {
  std::string osm;  // file (.osm, .osm.gz, .osm.bz2, .osm.pbf), relative paths from the config's directory
  osm::RoutingProfile profile;
  NavigatorConfig navigator;
};

// Throws ConfigError (file, line and key) for anything unusable; the OSM file
// must exist (it is read when trailnavd starts).
NavigationSection parse_navigation_section(const ConfigNode& node);

}  // namespace trailnav::nav
