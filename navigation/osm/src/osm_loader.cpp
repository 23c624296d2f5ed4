// load_road_graph: libosmium reads the file (any of its formats), node
// locations are kept in a FlexMem index (dense or sparse as the ids
// require), and each routable way is cut at blocked or missing nodes.
#include <GeographicLib/UTMUPS.hpp>
#include <algorithm>
#include <filesystem>
#include <osmium/handler.hpp>
#include <osmium/handler/node_locations_for_ways.hpp>
#include <osmium/index/map/flex_mem.hpp>
#include <osmium/io/any_input.hpp>
#include <osmium/visitor.hpp>
#include <unordered_map>
#include <unordered_set>

#include "trailnav/navigation/osm/road_graph.hpp"

namespace trailnav::osm {
namespace {

bool contains(const std::vector<std::string>& list, const char* value) {
  return value != nullptr && std::find(list.begin(), list.end(), value) != list.end();
}

struct WayPiece {
  std::uint32_t way = 0;
  int oneway = 0;
  std::vector<std::int64_t> nodes;
};

struct NodeGeo {
  double lat = 0.0, lon = 0.0;
};

class RoadHandler : public osmium::handler::Handler {
 public:
  RoadHandler(const RoutingProfile& profile, RoadGraphStats& stats) : profile_(profile), stats_(stats) {}

  void node(const osmium::Node& node) {
    ++stats_.nodes_read;
    const osmium::TagList& tags = node.tags();
    if (contains(profile_.blocking_barriers, tags.get_value_by_key("barrier")) ||
        contains(profile_.closed_access, tags.get_value_by_key("access")) ||
        contains(profile_.closed_access, tags.get_value_by_key("vehicle"))) {
      blocked_.insert(node.id());
    }
  }

  void way(const osmium::Way& way) {
    ++stats_.ways_read;
    const osmium::TagList& tags = way.tags();
    if (!contains(profile_.highways, tags.get_value_by_key("highway"))) return;
    if (contains(profile_.closed_access, tags.get_value_by_key("access")) ||
        contains(profile_.closed_access, tags.get_value_by_key("vehicle"))) {
      ++stats_.closed_ways;
      return;
    }
    ++stats_.routable_ways;
    int dir = 0;
    if (profile_.respect_oneway) {
      const char* ow = tags.get_value_by_key("oneway", "");
      const char* junction = tags.get_value_by_key("junction", "");
      dir = oneway_direction(ow, junction);
      if (dir != 0) ++stats_.oneway_ways;
    }
    const auto index = static_cast<std::uint32_t>(ways.size());
    RoadWay w;
    w.osm_id = way.id();
    w.highway = tags.get_value_by_key("highway");
    w.name = tags.get_value_by_key("name", "");
    ways.push_back(std::move(w));

    WayPiece piece{index, dir, {}};
    auto flush = [&] {
      if (piece.nodes.size() >= 2) pieces.push_back(piece);
      piece.nodes.clear();
    };
    for (const osmium::NodeRef& ref : way.nodes()) {
      const bool missing = !ref.location().valid();
      const bool blocked = blocked_.count(ref.ref()) != 0;
      if (missing) ++stats_.missing_nodes;
      if (blocked) ++stats_.blocked_nodes;
      if (missing || blocked) {
        flush();
        continue;
      }
      // A node repeated right after itself (an OSM data error) is one vertex.
      if (!piece.nodes.empty() && piece.nodes.back() == ref.ref()) {
        ++stats_.repeated_nodes;
        continue;
      }
      geo.try_emplace(ref.ref(), NodeGeo{ref.location().lat(), ref.location().lon()});
      piece.nodes.push_back(ref.ref());
    }
    flush();
  }

  std::vector<RoadWay> ways;
  std::vector<WayPiece> pieces;
  std::unordered_map<std::int64_t, NodeGeo> geo;

 private:
  const RoutingProfile& profile_;
  RoadGraphStats& stats_;
  std::unordered_set<std::int64_t> blocked_;
};

}  // namespace

namespace {

// Reads `file` (named `name` in messages) into `result`.
void read_road_graph(osmium::io::File file, const std::string& name, const RoutingProfile& profile,
                     const std::function<void(double)>& progress, int zone, RoadGraphResult& result);

}  // namespace

RoadGraphResult load_road_graph(const std::string& path, const RoutingProfile& profile,
                                const std::function<void(double)>& progress, int zone) {
  RoadGraphResult result;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    result.error = path + ": no such OpenStreetMap file";
    return result;
  }
  if (std::filesystem::file_size(path, ec) == 0) {
    result.error = path + ": the file is empty";
    return result;
  }
  try {
    read_road_graph(osmium::io::File(path), path, profile, progress, zone, result);
  } catch (const std::exception& e) {
    result.error = path + ": not readable as OpenStreetMap data: " + e.what();
  }
  return result;
}

RoadGraphResult parse_road_graph(std::span<const char> data, const std::string& name, const RoutingProfile& profile,
                                 int zone) {
  RoadGraphResult result;
  if (data.empty()) {
    result.error = name + ": no data";
    return result;
  }
  // XML starts with '<' (after any white space); anything else is read as PBF.
  const auto first = std::find_if(data.begin(), data.end(), [](char c) { return c != ' ' && c != '\t' && c != '\r' && c != '\n'; });
  const char* format = first != data.end() && *first == '<' ? "osm" : "pbf";
  try {
    read_road_graph(osmium::io::File(data.data(), data.size(), format), name, profile, {}, zone, result);
  } catch (const std::exception& e) {
    result.error = name + ": not readable as OpenStreetMap data: " + e.what();
  }
  return result;
}

namespace {

void read_road_graph(osmium::io::File file, const std::string& name, const RoutingProfile& profile,
                     const std::function<void(double)>& progress, int zone, RoadGraphResult& result) {
  if (profile.highways.empty()) {
    result.error = name + ": the routing profile lists no highway types";
    return;
  }
  RoadHandler handler(profile, result.stats);
  {
    using Index = osmium::index::map::FlexMem<osmium::unsigned_object_id_type, osmium::Location>;
    Index index;
    osmium::handler::NodeLocationsForWays<Index> locations(index);
    locations.ignore_errors();  // missing nodes are counted by the handler
    osmium::io::Reader reader(file, osmium::osm_entity_bits::node | osmium::osm_entity_bits::way);
    const double size = static_cast<double>(std::max<std::size_t>(1, reader.file_size()));
    while (osmium::memory::Buffer buffer = reader.read()) {
      osmium::apply(buffer, locations, handler);
      if (progress) progress(std::min(1.0, static_cast<double>(reader.offset()) / size));
    }
    reader.close();
  }
  if (progress) progress(1.0);
  if (result.stats.nodes_read == 0 && result.stats.ways_read == 0) {
    result.error = name + ": contains no OpenStreetMap nodes or ways";
    return;
  }
  if (handler.pieces.empty()) {
    std::string types;
    for (const auto& h : profile.highways) types += (types.empty() ? "" : ", ") + h;
    result.error = name + ": no routable way (" + std::to_string(result.stats.ways_read) + " ways read; none open with highway " +
                   types + " and two known nodes)";
    return;
  }

  // The zone: that of the centre of the routable nodes' bounding box.
  double lat0 = 90.0, lat1 = -90.0, lon0 = 180.0, lon1 = -180.0;
  for (const auto& [id, g] : handler.geo) {
    lat0 = std::min(lat0, g.lat); lat1 = std::max(lat1, g.lat);
    lon0 = std::min(lon0, g.lon); lon1 = std::max(lon1, g.lon);
  }
  const double clat = 0.5 * (lat0 + lat1), clon = 0.5 * (lon0 + lon1);
  if (std::abs(lat0) > 84.0 || std::abs(lat1) > 84.0) {
    result.error = name + ": the routable network reaches beyond 84 degrees latitude, where UTM is not defined";
    return;
  }
  if (zone == 0) zone = GeographicLib::UTMUPS::StandardZone(clat, clon);
  if (zone < 1 || zone > 60) {
    result.error = name + ": UTM zone " + std::to_string(zone) + " is not 1..60";
    return;
  }

  // Vertices in first-seen order of the pieces (deterministic for a file).
  const bool north = clat >= 0.0;
  std::unordered_map<std::int64_t, std::uint32_t> vertex_of;
  vertex_of.reserve(handler.geo.size());
  std::vector<RoadVertex> vertices;
  std::vector<std::vector<std::uint32_t>> way_vertices;
  std::vector<RoadWay> ways;
  std::vector<int> oneway;
  way_vertices.reserve(handler.pieces.size());
  for (const WayPiece& p : handler.pieces) {
    std::vector<std::uint32_t> vs;
    vs.reserve(p.nodes.size());
    for (std::int64_t id : p.nodes) {
      auto [it, inserted] = vertex_of.try_emplace(id, static_cast<std::uint32_t>(vertices.size()));
      if (inserted) {
        const NodeGeo& g = handler.geo.at(id);
        RoadVertex v;
        v.osm_id = id;
        utm_in_zone(zone, north, g.lat, g.lon, v.x, v.y);
        vertices.push_back(v);
      }
      vs.push_back(it->second);
    }
    way_vertices.push_back(std::move(vs));
    ways.push_back(handler.ways[p.way]);
    oneway.push_back(p.oneway);
  }
  result.graph = RoadGraph::build(zone, north, std::move(vertices), std::move(ways), way_vertices, oneway);
}

}  // namespace

}  // namespace trailnav::osm
