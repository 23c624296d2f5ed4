#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "test_data.hpp"
#include "trailnav/drivers/velodyne/calibration.hpp"

namespace trailnav::velodyne {
namespace {

using test::shared_data;

Calibration load(const std::string& name) {
  CalibrationResult r = load_calibration(shared_data("velodyne/calibration/" + name));
  EXPECT_TRUE(r.calibration.has_value()) << r.error;
  return r.calibration.value_or(Calibration{});
}

// The YAML was generated from the XML by converting degrees to radians and
// centimetres to metres; both files must give the same table.
void expect_same_table(const Calibration& yaml, const Calibration& xml, bool compare_intensity_limits = true) {
  ASSERT_EQ(yaml.lasers.size(), xml.lasers.size());
  for (std::size_t i = 0; i < yaml.lasers.size(); ++i) {
    const LaserCorrection& a = yaml.lasers[i];
    const LaserCorrection& b = xml.lasers[i];
    SCOPED_TRACE("laser " + std::to_string(i));
    EXPECT_EQ(a.laser_id, b.laser_id);
    EXPECT_NEAR(a.rot_correction, b.rot_correction, 1e-7);
    EXPECT_NEAR(a.vert_correction, b.vert_correction, 1e-7);
    EXPECT_NEAR(a.dist_correction, b.dist_correction, 1e-7);
    EXPECT_NEAR(a.dist_correction_x, b.dist_correction_x, 1e-7);
    EXPECT_NEAR(a.dist_correction_y, b.dist_correction_y, 1e-7);
    EXPECT_NEAR(a.vert_offset_correction, b.vert_offset_correction, 1e-7);
    EXPECT_NEAR(a.horiz_offset_correction, b.horiz_offset_correction, 1e-7);
    EXPECT_NEAR(a.focal_distance, b.focal_distance, 1e-7);
    EXPECT_NEAR(a.focal_slope, b.focal_slope, 1e-7);
    EXPECT_EQ(a.two_pt_correction, b.two_pt_correction);
    if (compare_intensity_limits) {
      EXPECT_EQ(a.min_intensity, b.min_intensity);
      EXPECT_EQ(a.max_intensity, b.max_intensity);
    }
  }
}

TEST(VelodyneCalibration, Hdl32eYamlAndXmlGiveTheSameTable) {
  const Calibration yaml = load("ros_velodyne_32db.yaml");
  const Calibration xml = load("ros_velodyne_tests_32db.xml");
  EXPECT_EQ(yaml.lasers.size(), 32u);
  expect_same_table(yaml, xml);
  EXPECT_TRUE(check_calibration(xml, Model::hdl32e));
}

TEST(VelodyneCalibration, Hdl64eSztakiYamlAndXmlGiveTheSameTable) {
  const Calibration yaml = load("ros_velodyne_64e_s2.1-sztaki.yaml");
  const Calibration xml = load("ros_velodyne_tests_64e_s2.1-sztaki.xml");
  EXPECT_EQ(yaml.lasers.size(), 64u);
  expect_same_table(yaml, xml, /*compare_intensity_limits=*/false);
  // Where the pair disagrees: the YAML's min_intensity values are the XML's
  // non-zero ones packed to the front — the converter that made the YAML
  // dropped the zeros — so from the first laser with a zero on, the YAML's
  // values belong to later lasers (max_intensity is mangled likewise). We
  // read the XML as written and prove the YAML's minima are that list, packed.
  auto packed = [](const Calibration& c, bool min, int default_value) {
    std::vector<int> out;
    for (const LaserCorrection& l : c.lasers) {
      const int v = min ? l.min_intensity : l.max_intensity;
      if (v != default_value) out.push_back(v);
    }
    return out;
  };
  auto leading = [](const Calibration& c, bool min, std::size_t n) {
    std::vector<int> out;
    for (std::size_t i = 0; i < n; ++i) out.push_back(min ? c.lasers[i].min_intensity : c.lasers[i].max_intensity);
    return out;
  };
  const std::vector<int> xml_min = packed(xml, true, 0);
  EXPECT_EQ(leading(yaml, true, xml_min.size()), xml_min);
  EXPECT_EQ(yaml.lasers[0].max_intensity, xml.lasers[0].max_intensity);
  EXPECT_EQ(xml.lasers[0].min_intensity, 0);
  EXPECT_EQ(xml.lasers[1].min_intensity, 30);
  EXPECT_TRUE(yaml.lasers[0].two_pt_correction);
  EXPECT_EQ(yaml.lasers[0].max_intensity, 235);
  EXPECT_NEAR(*xml.distance_resolution, 0.002, 1e-12);
  EXPECT_TRUE(check_calibration(yaml, Model::hdl64e));
}

// The built-in tables must agree with real units' files of the same model.
void expect_angles_match(const Calibration& builtin, const Calibration& file) {
  ASSERT_EQ(builtin.lasers.size(), file.lasers.size());
  for (std::size_t i = 0; i < file.lasers.size(); ++i) {
    EXPECT_NEAR(builtin.lasers[i].vert_correction, file.lasers[i].vert_correction, 2e-5) << "laser " << i;
    EXPECT_NEAR(builtin.lasers[i].rot_correction, file.lasers[i].rot_correction, 2e-5) << "laser " << i;
  }
}

TEST(VelodyneCalibration, BuiltInTablesMatchTheFiles) {
  expect_angles_match(*builtin_calibration(Model::vlp16), load("ros_velodyne_VLP16db.yaml"));
  expect_angles_match(*builtin_calibration(Model::vlp16_hires), load("ros_velodyne_VLP16_hires_db.yaml"));
  expect_angles_match(*builtin_calibration(Model::vlp32c), load("ros_velodyne_VeloView-VLP-32C.yaml"));
  expect_angles_match(*builtin_calibration(Model::hdl32e), load("ros_velodyne_32db.yaml"));
  EXPECT_FALSE(builtin_calibration(Model::hdl64e).has_value());
}

TEST(VelodyneCalibration, EveryShippedRosFileLoadsAndChecksAgainstItsModel) {
  EXPECT_TRUE(check_calibration(load("ros_velodyne_64e_utexas.yaml"), Model::hdl64e));
  EXPECT_TRUE(check_calibration(load("ros_velodyne_64e_s3-xiesc.yaml"), Model::hdl64e));
  EXPECT_TRUE(check_calibration(load("ros_velodyne_VeloView-VLP-32C.yaml"), Model::vlp32c));
  EXPECT_TRUE(check_calibration(load("ros_velodyne_VLP16db.yaml"), Model::vlp16));
}

TEST(VelodyneCalibration, WrongModelIsAClearError) {
  const Status s = check_calibration(load("ros_velodyne_32db.yaml"), Model::vlp16);
  ASSERT_FALSE(s);
  EXPECT_NE(s.message().find("has 32 lasers, but a VLP-16 has 16"), std::string::npos) << s.message();
}

TEST(VelodyneCalibration, BrokenFilesGiveErrorsWithTheFileName) {
  const CalibrationResult missing = load_calibration("/nonexistent/calib.yaml");
  EXPECT_FALSE(missing.calibration);
  EXPECT_NE(missing.error.find("/nonexistent/calib.yaml"), std::string::npos);
  // A YAML file that is not a calibration.
  const CalibrationResult wrong = load_calibration_yaml(shared_data("velodyne/nebula-vlp16/metadata.yaml"));
  EXPECT_FALSE(wrong.calibration);
  EXPECT_NE(wrong.error.find("expected a 'lasers' list"), std::string::npos) << wrong.error;
}

}  // namespace
}  // namespace trailnav::velodyne
