#include "trailnav/drivers/velodyne/calibration.hpp"

#include <expat.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>

namespace trailnav::velodyne {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kCmToM = 0.01;

std::optional<std::string> read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return std::nullopt;
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A loaded table, indexed by laser id whatever order the file listed them in.
CalibrationResult success(Calibration cal) {
  std::sort(cal.lasers.begin(), cal.lasers.end(),
            [](const LaserCorrection& a, const LaserCorrection& b) { return a.laser_id < b.laser_id; });
  CalibrationResult r;
  r.calibration = std::move(cal);
  return r;
}

CalibrationResult failure(const std::string& path, int line, const std::string& what) {
  CalibrationResult r;
  r.error = path + (line > 0 ? ":" + std::to_string(line) : std::string()) + ": " + what;
  return r;
}

// --- ROS YAML ---

double yaml_number(const YAML::Node& laser, const char* key, double fallback, bool& ok, std::string& bad_key) {
  const YAML::Node v = laser[key];
  if (!v.IsDefined() || v.IsNull()) return fallback;
  try {
    return v.as<double>();
  } catch (const YAML::Exception&) {
    ok = false;
    bad_key = key;
    return fallback;
  }
}

// --- Velodyne db.xml (boost serialization XML) ---

// Collects the values of the elements we need while expat walks the file:
// per-laser <px> fields, and the <enabled_>, <minIntensity_>, <maxIntensity_>
// lists and <distLSB_>.
struct XmlState {
  std::vector<std::string> path;  // element names from the root
  std::string text;
  std::vector<std::map<std::string, double>> px;
  std::vector<int> enabled;
  std::vector<int> min_intensity;
  std::vector<int> max_intensity;
  std::optional<double> dist_lsb_cm;
  std::string error;
  int error_line = 0;
  XML_Parser parser = nullptr;
};

void XMLCALL on_start(void* user, const XML_Char* name, const XML_Char**) {
  auto& s = *static_cast<XmlState*>(user);
  s.path.emplace_back(name);
  s.text.clear();
  if (s.path.back() == "px") s.px.emplace_back();
}

void XMLCALL on_text(void* user, const XML_Char* text, int length) {
  static_cast<XmlState*>(user)->text.append(text, static_cast<std::size_t>(length));
}

bool parse_number(const std::string& text, double& out) {
  std::size_t used = 0;
  try {
    out = std::stod(text, &used);
  } catch (const std::exception&) {
    return false;
  }
  while (used < text.size() && std::isspace(static_cast<unsigned char>(text[used])) != 0) ++used;
  return used == text.size() && std::isfinite(out);
}

void XMLCALL on_end(void* user, const XML_Char*) {
  auto& s = *static_cast<XmlState*>(user);
  const std::string name = s.path.back();
  const std::string parent = s.path.size() >= 2 ? s.path[s.path.size() - 2] : std::string();
  auto number = [&](double& out) {
    if (parse_number(s.text, out)) return true;
    if (s.error.empty()) {
      s.error = "<" + name + "> holds '" + s.text + "', not a number";
      s.error_line = static_cast<int>(XML_GetCurrentLineNumber(s.parser));
    }
    return false;
  };
  double v = 0.0;
  if (parent == "px" && !s.px.empty() && name.back() == '_') {
    if (number(v)) s.px.back()[name] = v;
  } else if (name == "item" && (parent == "enabled_" || parent == "minIntensity_" || parent == "maxIntensity_")) {
    if (number(v)) {
      auto& list = parent == "enabled_" ? s.enabled : parent == "minIntensity_" ? s.min_intensity : s.max_intensity;
      list.push_back(static_cast<int>(v));
    }
  } else if (name == "distLSB_") {
    if (number(v)) s.dist_lsb_cm = v;
  }
  s.path.pop_back();
  s.text.clear();
}

// The built-in tables: elevation in degrees by laser id.
constexpr double kVlp16Elevations[16] = {-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15};
constexpr double kVlp16HiResElevations[16] = {-10.0, 0.667, -8.667, 2.0, -7.333, 3.333, -6.0, 4.667,
                                              -4.667, 6.0, -3.333, 7.333, -2.0, 8.667, -0.667, 10.0};
constexpr double kHdl32eElevations[32] = {-30.67, -9.33, -29.33, -8.0,  -28.0,  -6.67, -26.67, -5.33,
                                          -25.33, -4.0,  -24.0,  -2.67, -22.67, -1.33, -21.33, 0.0,
                                          -20.0,  1.33,  -18.67, 2.67,  -17.33, 4.0,   -16.0,  5.33,
                                          -14.67, 6.67,  -13.33, 8.0,   -12.0,  9.33,  -10.67, 10.67};
// VLP-32C: elevation and azimuth offset (degrees) by laser id; a positive
// offset means the laser fires that far clockwise of the reported azimuth.
constexpr double kVlp32cElevations[32] = {-25, -1, -1.667, -15.639, -11.31, 0, -0.667, -8.843, -7.254, 0.333, -0.333,
                                          -6.148, -5.333, 1.333, 0.667, -4, -4.667, 1.667, 1, -3.667, -3.333, 3.333,
                                          2.333, -2.667, -3, 7, 4.667, -2.333, -2, 15, 10.333, -1.333};
constexpr double kVlp32cAzimuthOffsets[32] = {1.4, -4.2, 1.4, -1.4, 1.4, -1.4, 4.2, -1.4, 1.4, -4.2, 1.4,
                                              -1.4, 4.2, -1.4, 4.2, -1.4, 1.4, -4.2, 1.4, -4.2, 4.2, -1.4,
                                              1.4, -1.4, 1.4, -1.4, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4};

}  // namespace

CalibrationResult load_calibration_yaml(const std::string& path) {
  const auto text = read_file(path);
  if (!text) return failure(path, 0, "cannot open the calibration file");
  YAML::Node root;
  try {
    root = YAML::Load(*text);
  } catch (const YAML::Exception& e) {
    return failure(path, e.mark.line + 1, "YAML syntax error: " + e.msg);
  }
  if (!root.IsMap() || !root["lasers"].IsSequence()) {
    return failure(path, 1, "not a velodyne_pointcloud calibration: expected a 'lasers' list");
  }
  Calibration cal;
  cal.source = path;
  for (const YAML::Node& laser : root["lasers"]) {
    const int line = laser.Mark().line + 1;
    if (!laser.IsMap()) return failure(path, line, "each entry of 'lasers' must be a mapping");
    bool ok = true;
    std::string bad;
    LaserCorrection c;
    c.laser_id = static_cast<int>(yaml_number(laser, "laser_id", -1, ok, bad));
    c.rot_correction = yaml_number(laser, "rot_correction", 0, ok, bad);
    c.vert_correction = yaml_number(laser, "vert_correction", 0, ok, bad);
    c.dist_correction = yaml_number(laser, "dist_correction", 0, ok, bad);
    c.dist_correction_x = yaml_number(laser, "dist_correction_x", 0, ok, bad);
    c.dist_correction_y = yaml_number(laser, "dist_correction_y", 0, ok, bad);
    c.vert_offset_correction = yaml_number(laser, "vert_offset_correction", 0, ok, bad);
    c.horiz_offset_correction = yaml_number(laser, "horiz_offset_correction", 0, ok, bad);
    c.focal_distance = yaml_number(laser, "focal_distance", 0, ok, bad);
    c.focal_slope = yaml_number(laser, "focal_slope", 0, ok, bad);
    c.min_intensity = static_cast<int>(yaml_number(laser, "min_intensity", 0, ok, bad));
    c.max_intensity = static_cast<int>(yaml_number(laser, "max_intensity", 255, ok, bad));
    if (laser["two_pt_correction_available"].IsDefined()) {
      try {
        c.two_pt_correction = laser["two_pt_correction_available"].as<bool>();
      } catch (const YAML::Exception&) {
        ok = false;
        bad = "two_pt_correction_available";
      }
    }
    if (!ok) return failure(path, line, "laser entry: '" + bad + "' is not a number");
    if (c.laser_id < 0) return failure(path, line, "laser entry without laser_id");
    cal.lasers.push_back(c);
  }
  if (root["distance_resolution"].IsDefined()) {
    try {
      cal.distance_resolution = root["distance_resolution"].as<double>();
    } catch (const YAML::Exception&) {
      return failure(path, root["distance_resolution"].Mark().line + 1, "'distance_resolution' is not a number");
    }
  }
  return success(std::move(cal));
}

CalibrationResult load_calibration_xml(const std::string& path) {
  const auto text = read_file(path);
  if (!text) return failure(path, 0, "cannot open the calibration file");
  XmlState state;
  XML_Parser parser = XML_ParserCreate(nullptr);
  state.parser = parser;
  XML_SetUserData(parser, &state);
  XML_SetElementHandler(parser, on_start, on_end);
  XML_SetCharacterDataHandler(parser, on_text);
  const bool parsed = XML_Parse(parser, text->data(), static_cast<int>(text->size()), 1) == XML_STATUS_OK;
  const int line = static_cast<int>(XML_GetCurrentLineNumber(parser));
  const std::string xml_error = parsed ? std::string() : XML_ErrorString(XML_GetErrorCode(parser));
  XML_ParserFree(parser);
  if (!parsed) return failure(path, line, "XML error: " + xml_error);
  if (!state.error.empty()) return failure(path, state.error_line, state.error);
  if (state.px.empty()) return failure(path, 0, "not a Velodyne db.xml: no <px> laser entries");

  Calibration cal;
  cal.source = path;
  if (state.dist_lsb_cm) cal.distance_resolution = *state.dist_lsb_cm * kCmToM;
  for (std::size_t i = 0; i < state.px.size(); ++i) {
    if (i < state.enabled.size() && state.enabled[i] == 0) continue;
    const auto& f = state.px[i];
    auto get = [&](const char* key) {
      const auto it = f.find(key);
      return it == f.end() ? 0.0 : it->second;
    };
    LaserCorrection c;
    c.laser_id = static_cast<int>(f.count("id_") != 0 ? get("id_") : static_cast<double>(i));
    c.rot_correction = get("rotCorrection_") * kDegToRad;
    c.vert_correction = get("vertCorrection_") * kDegToRad;
    c.dist_correction = get("distCorrection_") * kCmToM;
    c.dist_correction_x = get("distCorrectionX_") * kCmToM;
    c.dist_correction_y = get("distCorrectionY_") * kCmToM;
    c.two_pt_correction = c.dist_correction_x != 0.0 || c.dist_correction_y != 0.0;
    c.vert_offset_correction = get("vertOffsetCorrection_") * kCmToM;
    c.horiz_offset_correction = get("horizOffsetCorrection_") * kCmToM;
    c.focal_distance = get("focalDistance_") * kCmToM;
    c.focal_slope = get("focalSlope_");
    if (i < state.min_intensity.size()) c.min_intensity = state.min_intensity[i];
    if (i < state.max_intensity.size()) c.max_intensity = state.max_intensity[i];
    cal.lasers.push_back(c);
  }
  return success(std::move(cal));
}

CalibrationResult load_calibration(const std::string& path) {
  const auto text = read_file(path);
  if (!text) return failure(path, 0, "cannot open the calibration file");
  const auto first = text->find_first_not_of(" \t\r\n");
  if (first != std::string::npos && (*text)[first] == '<') return load_calibration_xml(path);
  return load_calibration_yaml(path);
}

std::optional<Calibration> builtin_calibration(Model model) {
  Calibration cal;
  cal.source = std::string("built-in ") + std::string(model_info(model).name);
  auto add = [&](int id, double elevation_deg, double azimuth_offset_deg) {
    LaserCorrection c;
    c.laser_id = id;
    c.vert_correction = elevation_deg * kDegToRad;
    c.rot_correction = -azimuth_offset_deg * kDegToRad;  // subtracted from the azimuth when decoding
    cal.lasers.push_back(c);
  };
  switch (model) {
    case Model::vlp16:
      for (int i = 0; i < 16; ++i) add(i, kVlp16Elevations[i], 0.0);
      return cal;
    case Model::vlp16_hires:
      for (int i = 0; i < 16; ++i) add(i, kVlp16HiResElevations[i], 0.0);
      return cal;
    case Model::vlp32c:
      for (int i = 0; i < 32; ++i) add(i, kVlp32cElevations[i], kVlp32cAzimuthOffsets[i]);
      return cal;
    case Model::hdl32e:
      for (int i = 0; i < 32; ++i) add(i, kHdl32eElevations[i], 0.0);
      return cal;
    case Model::hdl64e:
      return std::nullopt;
  }
  return std::nullopt;
}

Status check_calibration(const Calibration& calibration, Model model) {
  const ModelInfo& info = model_info(model);
  const std::string who = calibration.source + ": ";
  if (static_cast<int>(calibration.lasers.size()) != info.lasers) {
    return Status::error(who + "has " + std::to_string(calibration.lasers.size()) + " lasers, but a " +
                         std::string(info.name) + " has " + std::to_string(info.lasers));
  }
  for (int i = 0; i < info.lasers; ++i) {
    const LaserCorrection& c = calibration.lasers[static_cast<std::size_t>(i)];
    if (c.laser_id != i) return Status::error(who + "laser ids must be 0.." + std::to_string(info.lasers - 1) + " without gaps");
    if (std::abs(c.vert_correction) > std::numbers::pi / 2.0 || std::abs(c.rot_correction) > std::numbers::pi) {
      return Status::error(who + "laser " + std::to_string(i) + " has an angle out of range (are the units radians?)");
    }
    if (c.min_intensity < 0 || c.max_intensity > 255 || c.min_intensity >= c.max_intensity) {
      return Status::error(who + "laser " + std::to_string(i) + " has min_intensity/max_intensity outside 0..255");
    }
  }
  if (calibration.distance_resolution && !(*calibration.distance_resolution > 0.0 && *calibration.distance_resolution < 0.1)) {
    return Status::error(who + "distance_resolution must be in (0, 0.1) m");
  }
  return Status::ok();
}

}  // namespace trailnav::velodyne
