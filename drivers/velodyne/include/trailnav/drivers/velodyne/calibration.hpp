// Per-laser calibration of a Velodyne sensor, in SI units: metres and
// radians. Loaded from the ROS velodyne_pointcloud YAML format or from
// Velodyne's XML database (db.xml, centimetres and degrees); both give the
// same table. Built-in tables for the VLP-16, VLP-16 Hi-Res, VLP-32C and
// HDL-32E come from the manufacturer's documented angles.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "trailnav/drivers/velodyne/model.hpp"
#include "trailnav/runtime/status.hpp"

namespace trailnav::velodyne {

struct LaserCorrection {
  int laser_id = 0;
  double rot_correction = 0.0;         // rad, azimuth offset of the laser
  double vert_correction = 0.0;        // rad, elevation of the laser
  double dist_correction = 0.0;        // m, added to every distance
  bool two_pt_correction = false;      // use the x/y distance corrections (HDL-64E)
  double dist_correction_x = 0.0;      // m
  double dist_correction_y = 0.0;      // m
  double vert_offset_correction = 0.0;   // m, height of the laser's origin
  double horiz_offset_correction = 0.0;  // m, sideways offset of the laser's origin
  double focal_distance = 0.0;         // m (intensity correction, HDL-64E)
  double focal_slope = 0.0;            // (intensity correction, HDL-64E)
  int min_intensity = 0;
  int max_intensity = 255;

  friend bool operator==(const LaserCorrection&, const LaserCorrection&) = default;
};

struct Calibration {
  std::vector<LaserCorrection> lasers;  // indexed by laser id
  std::optional<double> distance_resolution;  // m per count, when the file states it
  std::string source;                   // file it came from, or "built-in <model>"
};

struct CalibrationResult {
  std::optional<Calibration> calibration;
  std::string error;  // file and what is wrong, when calibration is empty
};

// Loads a ROS velodyne_pointcloud YAML calibration.
CalibrationResult load_calibration_yaml(const std::string& path);
// Loads a Velodyne XML database (db.xml); only lasers marked enabled are kept.
CalibrationResult load_calibration_xml(const std::string& path);
// Chooses the loader by the file's content (XML or YAML).
CalibrationResult load_calibration(const std::string& path);

// The manufacturer's nominal table, for the models that have one; nullopt
// for the HDL-64E, which always needs its unit's own calibration.
std::optional<Calibration> builtin_calibration(Model model);

// Checks a table against a model: laser count, ids in order, sane angles.
Status check_calibration(const Calibration& calibration, Model model);

}  // namespace trailnav::velodyne
