// The samples trailnavd writes, as they leave Cyclone DDS, byte for byte
// against XCDR1 (plain CDR, little endian) built here field by field from the
// ROS 2 .msg definitions — what rmw_cyclonedds_cpp puts on the wire for the
// same message. The samples go through a real writer and a real reader on a
// loopback-only domain; the reader takes the serialized form (dds_takecdr).
#include <gtest/gtest.h>

#include <dds/ddsi/ddsi_serdata.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "dds.hpp"
#include "messages.hpp"
#include "trailnav/navigation/navigator/navigator.hpp"
#include "trailnav/navigation/pose/gyro_odometry.hpp"
#include "trailnav/navigation/pose/utm_alignment.hpp"
#include "trailnav/perception/obstacle_task.hpp"

using namespace trailnav;

namespace {

// CDR as the OMG spec has it: primitives aligned to their size relative to
// the start of the body (8-byte types to 8 in XCDR1), strings as a uint32
// length counting the NUL, the bytes and the NUL; sequences as a uint32
// count and the elements; arrays as the elements only.
class Cdr {
 public:
  void align(std::size_t n) {
    while (body_.size() % n != 0) body_.push_back(0);
  }
  template <typename T>
  void put(T v) {
    align(sizeof(T));
    std::uint8_t raw[sizeof(T)];
    std::memcpy(raw, &v, sizeof(T));  // this machine is little endian, as CDR_LE
    body_.insert(body_.end(), raw, raw + sizeof(T));
  }
  void string(const std::string& s) {
    put<std::uint32_t>(static_cast<std::uint32_t>(s.size() + 1));
    body_.insert(body_.end(), s.begin(), s.end());
    body_.push_back(0);
  }
  // The serialized payload: the encapsulation header CDR_LE (0x0001) and its
  // options, whose two low bits count the padding that rounds the payload to
  // a multiple of four (DDS-XTypes 1.3, 7.6.3.1.2), then the body.
  std::vector<std::uint8_t> payload() const {
    const std::size_t pad = (4 - body_.size() % 4) % 4;
    std::vector<std::uint8_t> out(4 + body_.size() + pad, 0);
    out[1] = 0x01;
    out[3] = static_cast<std::uint8_t>(pad);
    for (std::size_t i = 0; i < body_.size(); ++i) out[4 + i] = body_[i];
    return out;
  }

 private:
  std::vector<std::uint8_t> body_;
};

void time(Cdr& c, std::int32_t sec, std::uint32_t nsec) {
  c.put(sec);
  c.put(nsec);
}
void header(Cdr& c, std::int32_t sec, std::uint32_t nsec, const std::string& frame) {
  time(c, sec, nsec);
  c.string(frame);
}
void put_pose(Cdr& c, const double (&p)[7]) {
  for (double v : p) c.put(v);
}

// Writes `sample` on a fresh topic and returns the bytes a reader receives.
std::vector<std::uint8_t> wire_bytes(const dds::Domain& domain, const dds_topic_descriptor_t& type,
                                     const std::string& name, const void* sample) {
  auto writer = dds::Writer::create(domain, type, name, {true, 1});
  EXPECT_TRUE(writer.writer) << writer.error;
  if (!writer.writer) return {};
  const dds_entity_t topic = dds_create_topic(domain.participant(), &type, dds::ros_topic(name).c_str(), nullptr, nullptr);
  EXPECT_GT(topic, 0);
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  const dds_entity_t reader = dds_create_reader(domain.participant(), topic, q, nullptr);
  dds_delete_qos(q);
  EXPECT_GT(reader, 0);
  EXPECT_TRUE(writer.writer->write(sample));
  std::vector<std::uint8_t> bytes;
  for (int i = 0; i < 200 && bytes.empty(); ++i) {
    ddsi_serdata* sd = nullptr;
    dds_sample_info_t info;
    if (dds_takecdr(reader, &sd, 1, &info, DDS_ANY_STATE) == 1) {
      bytes.resize(ddsi_serdata_size(sd));
      ddsi_serdata_to_ser(sd, 0, bytes.size(), bytes.data());
      ddsi_serdata_unref(sd);
    } else {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }
  dds_delete(reader);
  dds_delete(topic);
  return bytes;
}

class DdsTypes : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto d = dds::Domain::create(97, dds::loopback_config());
    ASSERT_TRUE(d.domain) << d.error;
    domain_ = d.domain.release();
  }
  static void TearDownTestSuite() {
    delete domain_;
    domain_ = nullptr;
  }
  static dds::Domain* domain_;
};
dds::Domain* DdsTypes::domain_ = nullptr;

}  // namespace

TEST_F(DdsTypes, TypeNamesAreTheOnesRos2Uses) {
  EXPECT_STREQ(nav_msgs_msg_dds__OccupancyGrid__desc.m_typename, "nav_msgs::msg::dds_::OccupancyGrid_");
  EXPECT_STREQ(nav_msgs_msg_dds__Path__desc.m_typename, "nav_msgs::msg::dds_::Path_");
  EXPECT_STREQ(geometry_msgs_msg_dds__PoseStamped__desc.m_typename, "geometry_msgs::msg::dds_::PoseStamped_");
  EXPECT_STREQ(geometry_msgs_msg_dds__PoseWithCovarianceStamped__desc.m_typename,
               "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_");
  EXPECT_STREQ(sensor_msgs_msg_dds__NavSatFix__desc.m_typename, "sensor_msgs::msg::dds_::NavSatFix_");
  EXPECT_STREQ(diagnostic_msgs_msg_dds__DiagnosticArray__desc.m_typename, "diagnostic_msgs::msg::dds_::DiagnosticArray_");
  EXPECT_STREQ(trailnav_msgs_msg_dds__TerrainClassMap__desc.m_typename, "trailnav_msgs::msg::dds_::TerrainClassMap_");
  EXPECT_EQ(dds::ros_topic("trailnav/obstacle_map"), "rt/trailnav/obstacle_map");
}

TEST_F(DdsTypes, OccupancyGridIsXcdr1AsRos2WritesIt) {
  perception::ObstacleSnapshot snap(3, 2);
  snap.resolution = 0.1;
  snap.origin_x = -30.05;
  snap.origin_y = 12.5;
  snap.time_ns = 1'700'000'123'456'789'000LL;
  snap.occupancy = {-1, 0, 100, 37, -1, 12};
  dds::OccupancyGridMessage m(3, 2, "odom");
  m.fill(snap, false);
  const auto got = wire_bytes(*domain_, nav_msgs_msg_dds__OccupancyGrid__desc, "t/grid", &m.sample());

  // nav_msgs/OccupancyGrid: std_msgs/Header header, MapMetaData info, int8[] data
  Cdr c;
  header(c, 1'700'000'123, 456'789'000u, "odom");
  time(c, 1'700'000'123, 456'789'000u);  // info.map_load_time
  c.put(0.1f);                           // resolution
  c.put(std::uint32_t{3});               // width
  c.put(std::uint32_t{2});               // height
  put_pose(c, {-30.05, 12.5, 0.0, 0.0, 0.0, 0.0, 1.0});  // origin: position, orientation (x y z w)
  c.put(std::uint32_t{6});
  for (std::int8_t v : snap.occupancy) c.put(v);
  EXPECT_EQ(got, c.payload());
}

TEST_F(DdsTypes, StaleGridKeepsObstaclesAndForgetsFreeCells) {
  perception::ObstacleSnapshot snap(4, 1);
  snap.occupancy = {-1, 0, 49, 100};
  dds::OccupancyGridMessage m(4, 1, "odom");
  m.fill(snap, true, 50);
  const std::int8_t* d = m.sample().data._buffer;
  EXPECT_EQ(d[0], -1);
  EXPECT_EQ(d[1], -1);
  EXPECT_EQ(d[2], -1);
  EXPECT_EQ(d[3], 100);
}

TEST_F(DdsTypes, PoseStampedIsXcdr1AsRos2WritesIt) {
  dds::PoseStampedMessage m("odom");
  m.fill(-5'000'000'001LL, 1.5, -2.25, 0.125, 0.0, 0.0, 0.5);  // before the epoch: sec -6, nanosec 999999999
  const auto got = wire_bytes(*domain_, geometry_msgs_msg_dds__PoseStamped__desc, "t/pose", &m.sample());
  Cdr c;
  header(c, -6, 999'999'999u, "odom");
  put_pose(c, {1.5, -2.25, 0.125, 0.0, 0.0, std::sin(0.25), std::cos(0.25)});
  EXPECT_EQ(got, c.payload());
}

TEST_F(DdsTypes, UtmPoseAndNavSatFixAreXcdr1AsRos2WritesThem) {
  pose::UtmPose u;
  u.position_valid = true;
  u.heading_valid = true;
  u.time_ns = 1'600'000'000'250'000'000LL;
  u.zone = 32;
  u.north = true;
  u.easting = 500'123.25;
  u.northing = 5'400'321.5;
  u.altitude = 312.0;
  u.yaw = 0.0;
  u.latitude = 48.75;
  u.longitude = 9.125;
  u.covariance << 4.0, 0.5, 0.01, 0.5, 9.0, 0.02, 0.01, 0.02, 0.04;
  dds::UtmFixMessages m("gps");
  ASSERT_TRUE(m.fill(u));

  const auto utm = wire_bytes(*domain_, geometry_msgs_msg_dds__PoseWithCovarianceStamped__desc, "t/utm", &m.utm());
  Cdr a;  // geometry_msgs/PoseWithCovarianceStamped: Header, PoseWithCovariance{Pose, float64[36]}
  header(a, 1'600'000'000, 250'000'000u, "utm_32N");
  put_pose(a, {500'123.25, 5'400'321.5, 312.0, 0.0, 0.0, 0.0, 1.0});
  double cov[36] = {};
  cov[0] = 4.0, cov[1] = 0.5, cov[5] = 0.01, cov[6] = 0.5, cov[7] = 9.0, cov[11] = 0.02;
  cov[14] = 1e6, cov[21] = 1e6, cov[28] = 1e6, cov[30] = 0.01, cov[31] = 0.02, cov[35] = 0.04;
  for (double v : cov) a.put(v);
  EXPECT_EQ(utm, a.payload());

  const auto fix = wire_bytes(*domain_, sensor_msgs_msg_dds__NavSatFix__desc, "t/fix", &m.fix());
  Cdr f;  // sensor_msgs/NavSatFix: Header, NavSatStatus{int8, uint16}, 3 x float64, float64[9], uint8
  header(f, 1'600'000'000, 250'000'000u, "gps");
  f.put(std::int8_t{0});
  f.put(std::uint16_t{1});
  f.put(48.75);
  f.put(9.125);
  f.put(312.0);
  for (double v : {4.0, 0.5, 0.0, 0.5, 9.0, 0.0, 0.0, 0.0, 36.0}) f.put(v);
  f.put(std::uint8_t{3});
  EXPECT_EQ(fix, f.payload());
}

TEST_F(DdsTypes, PathIsXcdr1AsRos2WritesIt) {
  dds::PathMessage m(8, "odom");
  m.clear(3'000'000'000LL);
  ASSERT_TRUE(m.add(3'100'000'000LL, 1.0, 2.0, 0.0));
  ASSERT_TRUE(m.add(3'200'000'000LL, 4.0, -1.0, 0.0));
  const auto got = wire_bytes(*domain_, nav_msgs_msg_dds__Path__desc, "t/path", &m.sample());
  Cdr c;  // nav_msgs/Path: Header, geometry_msgs/PoseStamped[]
  header(c, 3, 0u, "odom");
  c.put(std::uint32_t{2});
  header(c, 3, 100'000'000u, "odom");
  put_pose(c, {1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0});
  header(c, 3, 200'000'000u, "odom");
  put_pose(c, {4.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0});
  EXPECT_EQ(got, c.payload());
}

// A sample holds kStatuses statuses of kValues values: a status beyond them
// is dropped with its values (they never land on the status before it), a
// value beyond a status' room too, and both are counted.
TEST(Diagnostics, WhatDoesNotFitIsDroppedAndCountedNotAddedElsewhere) {
  dds::DiagnosticsMessage m;
  m.clear(1);
  m.value("before any status", std::uint64_t{1});
  EXPECT_EQ(m.dropped(), 1u);
  for (std::size_t k = 0; k < dds::DiagnosticsMessage::kStatuses; ++k) {
    ASSERT_TRUE(m.begin(dds::DiagnosticsMessage::ok, "status", "", ""));
  }
  for (std::size_t v = 0; v < dds::DiagnosticsMessage::kValues + 2; ++v) m.value("key", std::uint64_t{v});
  EXPECT_EQ(m.sample().status._buffer[dds::DiagnosticsMessage::kStatuses - 1].values._length, dds::DiagnosticsMessage::kValues);
  EXPECT_EQ(m.dropped(), 3u);
  EXPECT_FALSE(m.begin(dds::DiagnosticsMessage::warn, "one too many", "", ""));
  m.value("its value", std::uint64_t{9});
  EXPECT_EQ(m.sample().status._length, dds::DiagnosticsMessage::kStatuses);
  EXPECT_EQ(m.sample().status._buffer[dds::DiagnosticsMessage::kStatuses - 1].values._length, dds::DiagnosticsMessage::kValues);
  EXPECT_EQ(m.dropped(), 5u);
  m.clear(2);
  EXPECT_EQ(m.dropped(), 0u);
  ASSERT_TRUE(m.begin(dds::DiagnosticsMessage::ok, "fresh", "", ""));
  m.value("key", std::uint64_t{1});
  EXPECT_EQ(m.sample().status._buffer[0].values._length, 1u);
}

TEST_F(DdsTypes, DiagnosticArrayIsXcdr1AsRos2WritesIt) {
  dds::DiagnosticsMessage m;
  m.clear(10'000'000'500LL);
  ASSERT_TRUE(m.begin(dds::DiagnosticsMessage::warn, "trailnavd: lidar", "silent for 0.8 s", "VLP-16"));
  m.value("packets", std::uint64_t{7540});
  m.value("rpm", 599.5, 1);
  ASSERT_TRUE(m.begin(dds::DiagnosticsMessage::ok, "trailnavd: gps", "fix", ""));
  const auto got = wire_bytes(*domain_, diagnostic_msgs_msg_dds__DiagnosticArray__desc, "t/diag", &m.sample());
  // diagnostic_msgs/DiagnosticArray: Header, DiagnosticStatus[]; DiagnosticStatus:
  // byte level, string name, string message, string hardware_id, KeyValue[] values
  Cdr c;
  header(c, 10, 500u, "");
  c.put(std::uint32_t{2});
  c.put(std::uint8_t{1});
  c.string("trailnavd: lidar");
  c.string("silent for 0.8 s");
  c.string("VLP-16");
  c.put(std::uint32_t{2});
  c.string("packets");
  c.string("7540");
  c.string("rpm");
  c.string("599.5");
  c.put(std::uint8_t{0});
  c.string("trailnavd: gps");
  c.string("fix");
  c.string("");
  c.put(std::uint32_t{0});
  EXPECT_EQ(got, c.payload());
}

TEST_F(DdsTypes, TerrainClassMapIsTheDocumentedLayout) {
  dds::TerrainClassMapMessage m(2, 2, "odom");
  m.set_header(2'000'000'000LL, 0.2, -30.0, -30.0);
  const std::uint8_t ids[4] = {0, 2, 255, 3};
  const std::uint8_t conf[4] = {250, 128, 0, 77};
  std::memcpy(m.class_id(), ids, 4);
  std::memcpy(m.confidence(), conf, 4);
  const auto got = wire_bytes(*domain_, trailnav_msgs_msg_dds__TerrainClassMap__desc, "t/terrain", &m.sample());
  // Header, MapMetaData, string[] class_names, uint8[] class_id, uint8[] confidence
  Cdr c;
  header(c, 2, 0u, "odom");
  time(c, 2, 0u);
  c.put(0.2f);
  c.put(std::uint32_t{2});
  c.put(std::uint32_t{2});
  put_pose(c, {-30.0, -30.0, 0.0, 0.0, 0.0, 0.0, 1.0});
  c.put(std::uint32_t{5});
  for (const char* n : {"street", "dirt", "grass", "vegetation", "other"}) c.string(n);
  c.put(std::uint32_t{4});
  for (std::uint8_t v : ids) c.put(v);
  c.put(std::uint32_t{4});
  for (std::uint8_t v : conf) c.put(v);
  EXPECT_EQ(got, c.payload());
}

// tf2_msgs/TFMessage: TransformStamped[] transforms; each: Header header,
// string child_frame_id, Transform transform (Vector3 translation,
// Quaternion rotation).
TEST_F(DdsTypes, TfMessageIsXcdr1AsRos2WritesIt) {
  dds::TfMessage m(2);
  m.add(1'700'000'000'250'000'000LL, "odom", "base_link", {1.0, 2.0, 0.5, 0.0, 0.0, 0.5});
  m.add(1'700'000'000'250'000'000LL, "utm_32N", "odom", {412345.5, 5312345.25, 271.0, 0.0, 0.0, -1.0});
  EXPECT_FALSE(m.add(0, "a", "b", {}));  // full
  const auto got = wire_bytes(*domain_, tf2_msgs_msg_dds__TFMessage__desc, "t/tf", &m.sample());
  Cdr c;
  c.put(std::uint32_t{2});
  header(c, 1'700'000'000, 250'000'000u, "odom");
  c.string("base_link");
  put_pose(c, {1.0, 2.0, 0.5, 0.0, 0.0, std::sin(0.25), std::cos(0.25)});
  header(c, 1'700'000'000, 250'000'000u, "utm_32N");
  c.string("odom");
  put_pose(c, {412345.5, 5312345.25, 271.0, 0.0, 0.0, std::sin(-0.5), std::cos(-0.5)});
  EXPECT_EQ(got, c.payload());
  EXPECT_STREQ(tf2_msgs_msg_dds__TFMessage__desc.m_typename, "tf2_msgs::msg::dds_::TFMessage_");
}

// The utm -> odom transform puts the robot's odometry position on its UTM one.
TEST_F(DdsTypes, UtmToOdomMapsTheOdometryPoseOntoTheUtmPose) {
  pose::LocalPose local;
  local.x = 12.0;
  local.y = -3.0;
  local.z = 0.4;
  local.yaw = 0.3;
  pose::UtmPose utm;
  utm.easting = 412000.0;
  utm.northing = 5312000.0;
  utm.altitude = 270.0;
  utm.yaw = 1.2;
  const dds::RigidTransform t = dds::utm_to_odom(local, utm);
  EXPECT_NEAR(t.yaw, 0.9, 1e-12);
  EXPECT_NEAR(t.x + std::cos(t.yaw) * local.x - std::sin(t.yaw) * local.y, utm.easting, 1e-6);
  EXPECT_NEAR(t.y + std::sin(t.yaw) * local.x + std::cos(t.yaw) * local.y, utm.northing, 1e-6);
  EXPECT_NEAR(t.z + local.z, utm.altitude, 1e-9);
}

// nav_msgs/Odometry: Header header, string child_frame_id,
// PoseWithCovariance pose, TwistWithCovariance twist.
TEST_F(DdsTypes, OdometryIsXcdr1AsRos2WritesIt) {
  dds::OdometryMessage m("odom", "base_link");
  pose::LocalPose p;
  p.time_ns = 1'700'000'001'000'000'500LL;
  p.x = 3.0;
  p.y = 4.0;
  p.yaw = 0.5;
  p.speed = 1.25;
  p.yaw_rate = -0.1;
  p.distance = 10.0;
  m.fill(p);
  const auto got = wire_bytes(*domain_, nav_msgs_msg_dds__Odometry__desc, "t/odom", &m.sample());
  Cdr c;
  header(c, 1'700'000'001, 500u, "odom");
  c.string("base_link");
  put_pose(c, {3.0, 4.0, 0.0, 0.0, 0.0, std::sin(0.25), std::cos(0.25)});
  const double sp = 0.01 + 0.06 * 10.0, sy = 0.005 + 0.002 * 10.0;
  for (int i = 0; i < 36; ++i) {
    const double diag[6] = {sp * sp, sp * sp, sp * sp, 0.005 * 0.005, 0.005 * 0.005, sy * sy};
    c.put(i % 7 == 0 ? diag[i / 7] : 0.0);
  }
  for (double v : {1.25, 0.0, 0.0, 0.0, 0.0, -0.1}) c.put(v);
  for (int i = 0; i < 36; ++i) {
    const double diag[6] = {0.05 * 0.05, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4};
    c.put(i % 7 == 0 ? diag[i / 7] : 0.0);
  }
  EXPECT_EQ(got, c.payload());
  EXPECT_STREQ(nav_msgs_msg_dds__Odometry__desc.m_typename, "nav_msgs::msg::dds_::Odometry_");
}

// trailnav_msgs/NavigationStatus, the layout docs/dds.md gives.
TEST_F(DdsTypes, NavigationStatusIsTheDocumentedLayout) {
  nav::NavigationStatusReport r;
  r.time_ns = 1'700'000'002'000'000'000LL;
  r.state = nav::NavState::following;
  r.has_goal = true;
  r.goal_lat = 48.03;
  r.goal_lon = 7.81;
  r.goal_easting = 412000.5;
  r.goal_northing = 5320000.25;
  r.remaining = 150.5;
  r.route_length = 190.0;
  r.subgoals = 48;
  r.active = 10;
  r.zone = 32;
  r.north = true;
  r.counters.goals = 3;
  r.counters.goals_refused = 1;
  r.counters.cancels = 0;
  r.counters.plans = 2;
  std::snprintf(r.refusal.data(), r.refusal.size(), "goal refused: why");
  dds::NavigationStatusMessage m;
  m.fill(r, "utm_32N");
  const auto got = wire_bytes(*domain_, trailnav_msgs_msg_dds__NavigationStatus__desc, "t/status", &m.sample());
  Cdr c;
  header(c, 1'700'000'002, 0u, "utm_32N");
  c.put(std::uint8_t{2});
  c.string("following");
  c.string("goal refused: why");
  c.put(std::uint8_t{1});
  for (double v : {48.03, 7.81, 0.0, 412000.5, 5320000.25, 150.5, 190.0}) c.put(v);
  c.put(std::uint32_t{48});
  c.put(std::uint32_t{10});
  for (std::uint64_t v : {3u, 1u, 0u, 2u}) c.put(std::uint64_t{v});
  EXPECT_EQ(got, c.payload());
}

// The order types trailnavd reads: what ROS 2 names them.
TEST_F(DdsTypes, OrderTypesAreTheOnesRos2Uses) {
  EXPECT_STREQ(geographic_msgs_msg_dds__GeoPoseStamped__desc.m_typename, "geographic_msgs::msg::dds_::GeoPoseStamped_");
  EXPECT_STREQ(std_msgs_msg_dds__Empty__desc.m_typename, "std_msgs::msg::dds_::Empty_");
  geographic_msgs_msg_dds__GeoPoseStamped_ g{};
  char frame[] = "";
  g.header.frame_id = frame;
  g.pose.position = {48.0, 7.8, 300.0};
  g.pose.orientation.w = 1.0;
  const auto got = wire_bytes(*domain_, geographic_msgs_msg_dds__GeoPoseStamped__desc, "t/geo", &g);
  Cdr c;
  header(c, 0, 0u, "");
  put_pose(c, {48.0, 7.8, 300.0, 0.0, 0.0, 0.0, 1.0});
  EXPECT_EQ(got, c.payload());
}

// A PoseStamped goal's frame decides how it is read.
TEST(CommandReader, APoseGoalsFrameNamesItsKind) {
  dds::CommandReaderOptions o;
  o.zone = 32;
  o.north = true;
  geometry_msgs_msg_dds__PoseStamped_ p{};
  std::string frame = "odom";
  p.header.frame_id = frame.data();
  p.pose.position.x = 1.0;
  p.pose.position.y = 2.0;
  EXPECT_EQ(dds::goal_from_pose(p, o).goal.frame, nav::GoalFrame::odom);
  frame = "utm_32N";
  p.header.frame_id = frame.data();
  EXPECT_EQ(dds::goal_from_pose(p, o).goal.frame, nav::GoalFrame::utm);
  frame = "utm_33N";
  p.header.frame_id = frame.data();
  EXPECT_EQ(dds::goal_from_pose(p, o).goal.frame, nav::GoalFrame::unknown);
  o.map_frame = "map";
  frame = "map";
  p.header.frame_id = frame.data();
  EXPECT_EQ(dds::goal_from_pose(p, o).goal.frame, nav::GoalFrame::utm);
  p.header.frame_id = nullptr;  // as a C sample may have it
  const nav::NavCommand none = dds::goal_from_pose(p, o);
  EXPECT_EQ(none.goal.frame, nav::GoalFrame::unknown);
  EXPECT_EQ(none.goal.frame_id[0], '\0');
  std::string longer(100, 'x');
  p.header.frame_id = longer.data();
  EXPECT_EQ(std::string(dds::goal_from_pose(p, o).goal.frame_id.data()), std::string(47, 'x'));
}

// The coarse map: blocks aligned to the odometry frame's cell grid around the
// robot, an obstacle anywhere in a block makes it one, unknown only when all
// of a block is; a stale map forgets free blocks.
TEST(CoarseMap, BlocksKeepTheirObstaclesAndFollowTheRobot) {
  perception::ObstacleSnapshot snap(8, 8);
  snap.resolution = 0.5;
  snap.origin_x = -2.0;  // cells -4 .. 3 of the odometry grid
  snap.origin_y = 1.0;   // cells 2 .. 9
  snap.robot_x = 0.1;
  snap.robot_y = 3.2;
  std::fill(snap.occupancy.begin(), snap.occupancy.end(), std::int8_t{-1});
  auto at = [&](int x, int y) -> std::int8_t& { return snap.occupancy[static_cast<std::size_t>(y * 8 + x)]; };
  at(4, 4) = 10;   // grid cell (0, 6): block (0, 3)
  at(5, 4) = 90;   // grid cell (1, 6): same block
  at(4, 5) = 0;    // grid cell (0, 7): same block
  at(0, 0) = 20;   // grid cell (-4, 2): block (-2, 1)
  dds::OccupancyGridMessage m(3, 3, "odom");
  m.fill_coarse(snap, 2, false);
  // The robot's block is (0, 3) (1 m blocks); the 3 x 3 window starts at (-1, 2).
  EXPECT_FLOAT_EQ(m.sample().info.resolution, 1.0f);
  EXPECT_DOUBLE_EQ(m.sample().info.origin.position.x, -1.0);
  EXPECT_DOUBLE_EQ(m.sample().info.origin.position.y, 2.0);
  const std::int8_t* d = m.sample().data._buffer;
  EXPECT_EQ(d[1 * 3 + 1], 90);  // block (0, 3): the largest of 10, 90, 0
  EXPECT_EQ(d[0], -1);          // block (-1, 2): cells (-2..-1, 4..5), never seen
  for (int k : {2, 3, 5, 6, 7, 8}) EXPECT_EQ(d[k], -1) << k;
  dds::OccupancyGridMessage whole(4, 4, "odom");
  snap.robot_x = -0.1;  // block -1: a 4 x 4 window from (-3, 1) covers every cell
  whole.fill_coarse(snap, 2, false);
  EXPECT_EQ(whole.sample().data._buffer[0 * 4 + 1], 20);  // block (-2, 1)
  whole.fill_coarse(snap, 2, true);  // stale: the free blocks are forgotten, the obstacle stays
  EXPECT_EQ(whole.sample().data._buffer[0 * 4 + 1], -1);
  EXPECT_EQ(whole.sample().data._buffer[2 * 4 + 3], 90);
}

// The terrain map's two cost layers, row-major from the map's origin: the
// class costs (§8.1.2) and the learnt traversability, 100 (1 - P(trav)),
// each -1 where it knows nothing.
TEST(TerrainLayers, ClassCostsAndTheLearntTraversabilityAsOccupancyGrids) {
  perception::TerrainClassMap map({2, 2, 0.5});
  map.grid().move_to(0.0, 0.0);
  map.time_ns = 1'500'000'000;
  const CellIndex o = map.grid().origin();
  perception::TerrainCell& street = map.grid().at({o.x, o.y});
  street.set({1.0f, 0.0f, 0.0f, 0.0f, 0.0f});
  street.traversable = 0.9f;
  map.grid().at({o.x + 1, o.y}).traversable = 0.0f;  // a cell only the learnt layer saw: surely not
  map.grid().at({o.x, o.y + 1}).set({0.0f, 0.0f, 0.0f, 0.0f, 1.0f});  // `other`, no layer evidence
  dds::OccupancyGridMessage cost(2, 2, "odom"), trav(2, 2, "odom");
  cost.fill_cost(map, {0.1f, 0.2f, 0.4f, 0.8f, 1.0f}, 1.0f);
  trav.fill_traversability(map);
  const std::int8_t* c = cost.sample().data._buffer;
  const std::int8_t* t = trav.sample().data._buffer;
  EXPECT_EQ(c[0], 10);
  EXPECT_EQ(c[1], -1);
  EXPECT_EQ(c[2], 100);
  EXPECT_EQ(c[3], -1);
  EXPECT_EQ(t[0], 10);
  EXPECT_EQ(t[1], 100);
  EXPECT_EQ(t[2], -1);
  EXPECT_EQ(t[3], -1);
  EXPECT_EQ(trav.sample().header.stamp.sec, 1);
  EXPECT_DOUBLE_EQ(trav.sample().info.origin.position.x, o.x * 0.5);
  EXPECT_FLOAT_EQ(trav.sample().info.resolution, 0.5f);
}

// trailnavd's own Cyclone configuration: the shipped one with an 80 kB
// receive buffer, inside the Internal element it has or a new one.
TEST(CycloneConfig, TrailnavdsOwnReceiveBufferIsSmall) {
  const std::string with = dds::with_small_receive_buffer(dds::loopback_config());
  EXPECT_NE(with.find("<Internal><SocketReceiveBufferSize min=\"80kB\" max=\"80kB\"/>"), std::string::npos);
  EXPECT_EQ(with.find("<Internal>"), with.rfind("<Internal>"));  // still one Internal element
  const std::string bare = "<CycloneDDS><Domain Id=\"any\"><General/></Domain></CycloneDDS>";
  EXPECT_EQ(dds::with_small_receive_buffer(bare),
            "<CycloneDDS><Domain Id=\"any\"><General/><Internal><SocketReceiveBufferSize min=\"80kB\" max=\"80kB\"/>"
            "</Internal></Domain></CycloneDDS>");
  // Cyclone takes it (the loopback configuration only: nothing leaves lo).
  auto d = dds::Domain::create(98, with);
  EXPECT_TRUE(d.domain) << d.error;
}
