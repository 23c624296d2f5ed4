// `trailnav route`: plans on an OpenStreetMap extract from one position to
// another (A* on the routable network, thesis §8.1.1) and prints the route
// and its subgoals every `spacing` metres as GeoJSON or CSV.
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include "commands.hpp"
#include "terminal.hpp"
#include "trailnav/navigation/osm/road_graph.hpp"
#include "trailnav/navigation/osm/router.hpp"

namespace trailnav::cli {
namespace {

struct RouteOptions {
  std::string osm;
  std::string from, to;
  double spacing = 4.0;
  std::string format = "geojson";
  std::string out;
  std::vector<std::string> highways;
  bool ignore_oneway = false;
  double max_snap = 200.0;
  bool dijkstra = false;
  bool quiet = false;
};

bool parse_latlon(const std::string& text, double& lat, double& lon, std::string& error) {
  const auto comma = text.find(',');
  std::size_t used_lat = 0, used_lon = 0;
  try {
    if (comma == std::string::npos) throw std::invalid_argument("");
    lat = std::stod(text.substr(0, comma), &used_lat);
    lon = std::stod(text.substr(comma + 1), &used_lon);
  } catch (const std::exception&) {
    error = "'" + text + "' is not LAT,LON in decimal degrees (e.g. 47.1410,9.5209)";
    return false;
  }
  if (used_lat != comma || used_lon != text.size() - comma - 1 || !(std::abs(lat) <= 84.0) || !(std::abs(lon) <= 180.0)) {
    error = "'" + text + "' is not LAT,LON with latitude within +-84 and longitude within +-180 degrees";
    return false;
  }
  return true;
}

int run_route(const RouteOptions& o) {
  const char* who = "trailnav route";
  double from_lat = 0, from_lon = 0, to_lat = 0, to_lon = 0;
  std::string error;
  if (!parse_latlon(o.from, from_lat, from_lon, error) || !parse_latlon(o.to, to_lat, to_lon, error)) {
    std::fprintf(stderr, "%s: %s\n", who, error.c_str());
    return 2;
  }
  if (!(o.spacing >= 0.5 && o.spacing <= 1000.0)) {
    std::fprintf(stderr, "%s: --spacing %g m is outside 0.5..1000\n", who, o.spacing);
    return 2;
  }
  osm::RoutingProfile profile;
  if (!o.highways.empty()) profile.highways = o.highways;
  profile.respect_oneway = !o.ignore_oneway;

  ProgressBar bar(std::string("reading ") + o.osm, 100.0, "%");
  auto loaded = osm::load_road_graph(o.osm, profile, [&](double f) { if (!o.quiet) bar.update(100.0 * f); });
  if (!o.quiet) bar.finish();
  if (!loaded.graph) {
    std::fprintf(stderr, "%s: %s\n", who, loaded.error.c_str());
    return 1;
  }
  const osm::RoadGraph& graph = *loaded.graph;
  double fx = 0, fy = 0, tx = 0, ty = 0;
  graph.to_utm(from_lat, from_lon, fx, fy);
  graph.to_utm(to_lat, to_lon, tx, ty);
  const auto from = graph.project(fx, fy);
  const auto to = graph.project(tx, ty);
  for (const auto& [name, p] : {std::pair{"start", from}, std::pair{"goal", to}}) {
    if (p->distance > o.max_snap) {
      std::fprintf(stderr, "%s: the %s lies %.0f m from the nearest routable way (more than --max-snap %.0f m)\n", who, name,
                   p->distance, o.max_snap);
      return 1;
    }
  }
  osm::Router router(graph);
  std::vector<osm::Point2> path, goals;
  router.reserve_path(path);
  const osm::RouteStats stats =
      router.route(*from, *to, path, o.dijkstra ? osm::Router::Algorithm::dijkstra : osm::Router::Algorithm::astar);
  if (!stats.found) {
    std::fprintf(stderr, "%s: no route: the goal cannot be reached from the start on the routable network "
                         "(separate networks, oneway ways or barriers)\n", who);
    return 1;
  }
  osm::subsample_path(path, o.spacing, goals);

  std::ostringstream text;
  text.precision(10);
  auto latlon = [&](const osm::Point2& p, double& lat, double& lon) { graph.to_latlon(p.x, p.y, lat, lon); };
  if (o.format == "csv") {
    text << "kind,index,easting,northing,lat,lon\n";
    for (const auto& [kind, pts] : {std::pair{"route", &path}, std::pair{"subgoal", &goals}}) {
      for (std::size_t i = 0; i < pts->size(); ++i) {
        double lat = 0, lon = 0;
        latlon((*pts)[i], lat, lon);
        char line[160];
        std::snprintf(line, sizeof line, "%s,%zu,%.3f,%.3f,%.8f,%.8f\n", kind, i, (*pts)[i].x, (*pts)[i].y, lat, lon);
        text << line;
      }
    }
  } else {
    char buf[200];
    text << "{\"type\":\"FeatureCollection\",\"features\":[\n";
    text << "{\"type\":\"Feature\",\"properties\":{\"kind\":\"route\",\"length_m\":";
    std::snprintf(buf, sizeof buf, "%.2f,\"utm_zone\":%d}", stats.length, graph.zone());
    text << buf << ",\"geometry\":{\"type\":\"LineString\",\"coordinates\":[";
    for (std::size_t i = 0; i < path.size(); ++i) {
      double lat = 0, lon = 0;
      latlon(path[i], lat, lon);
      std::snprintf(buf, sizeof buf, "%s[%.8f,%.8f]", i ? "," : "", lon, lat);
      text << buf;
    }
    text << "]}}";
    for (std::size_t i = 0; i < goals.size(); ++i) {
      double lat = 0, lon = 0;
      latlon(goals[i], lat, lon);
      std::snprintf(buf, sizeof buf,
                    ",\n{\"type\":\"Feature\",\"properties\":{\"kind\":\"subgoal\",\"index\":%zu,\"easting\":%.3f,\"northing\":%.3f},",
                    i, goals[i].x, goals[i].y);
      text << buf;
      std::snprintf(buf, sizeof buf, "\"geometry\":{\"type\":\"Point\",\"coordinates\":[%.8f,%.8f]}}", lon, lat);
      text << buf;
    }
    text << "\n]}\n";
  }
  if (o.out.empty()) {
    std::fputs(text.str().c_str(), stdout);
  } else {
    std::FILE* f = std::fopen(o.out.c_str(), "w");
    if (f == nullptr || std::fputs(text.str().c_str(), f) < 0 || std::fclose(f) != 0) {
      std::fprintf(stderr, "%s: cannot write %s\n", who, o.out.c_str());
      return 1;
    }
  }
  std::fprintf(stderr,
               "%s: UTM zone %d%s, %zu vertices, %zu edges; start %.1f m and goal %.1f m off the network; "
               "route %.1f m, %zu subgoals every %g m (%llu vertices expanded)\n",
               who, graph.zone(), graph.north() ? "N" : "S", graph.vertex_count(), graph.edge_count(), from->distance,
               to->distance, stats.length, goals.size(), o.spacing, static_cast<unsigned long long>(stats.expanded));
  return 0;
}

}  // namespace

void add_route_command(CLI::App& app) {
  static RouteOptions route_options;
  RouteOptions* o = &route_options;
  CLI::App* cmd = app.add_subcommand(
      "route",
      "Plan on an OpenStreetMap extract (.osm, .osm.gz, .osm.bz2, .osm.pbf): the start and goal are projected onto\n"
      "the nearest routable way, A* finds the shortest path on the network, and the path is cut into subgoals\n"
      "every --spacing metres (thesis §8.1.1). Prints GeoJSON (the route as a LineString, subgoals as Points with\n"
      "their UTM easting/northing) or CSV (kind,index,easting,northing,lat,lon) on stdout, a summary on stderr.\n"
      "Example: trailnav route ../shared/data/osm/osm2pgsql_liechtenstein-2013-08-03.osm.pbf \\\n"
      "           --from 47.1410,9.5209 --to 47.1660,9.5100 --format csv");
  cmd->add_option("osm", o->osm, "OpenStreetMap file")->required();
  cmd->add_option("--from", o->from, "start LAT,LON (decimal degrees, WGS84)")->required();
  cmd->add_option("--to", o->to, "goal LAT,LON")->required();
  cmd->add_option("--spacing", o->spacing, "metres between subgoals")->capture_default_str();
  cmd->add_option("--format", o->format, "geojson or csv")->check(CLI::IsMember({"geojson", "csv"}))->capture_default_str();
  cmd->add_option("--out", o->out, "write the route here instead of stdout");
  cmd->add_option("--highways", o->highways,
                  "highway types the robot may use (comma-separated; default track, path, unclassified, residential,\n"
                  "service, living_street, tertiary, secondary, cycleway, bridleway, footway)")
      ->delimiter(',');
  cmd->add_flag("--ignore-oneway", o->ignore_oneway, "drive oneway ways in both directions");
  cmd->add_option("--max-snap", o->max_snap, "metres start and goal may lie off the network")->capture_default_str();
  cmd->add_flag("--dijkstra", o->dijkstra, "search without the A* heuristic (same result, slower; for comparison)");
  cmd->add_flag("-q,--quiet", o->quiet, "no progress bar");
  cmd->callback([o] { std::exit(run_route(*o)); });
}

}  // namespace trailnav::cli
