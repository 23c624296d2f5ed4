// The simulator: determinism, lidar points on the intended surfaces (range
// error against the configured noise), NMEA through the GPS parser, CAN
// through the shipped DBC, Xsens frames well formed, and scenario errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <unistd.h>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <numbers>
#include <sstream>

#include "camera.hpp"
#include "motion.hpp"
#include "roads.hpp"
#include "scenario.hpp"
#include "trailnav/drivers/imu/attitude.hpp"
#include "trailnav/drivers/imu/xsens.hpp"
#include "simulator.hpp"
#include "test_data.hpp"
#include "trailnav/drivers/can/dbc.hpp"
#include "trailnav/drivers/gps/nmea.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/drivers/velodyne/calibration.hpp"
#include "trailnav/drivers/velodyne/decoder.hpp"
#include "truth.hpp"
#include "world.hpp"

namespace {

namespace fs = std::filesystem;
using namespace trailnav;
using namespace trailnav::sim;

std::string temp_dir(const std::string& name) {
  const fs::path p = fs::temp_directory_path() / ("trailnav-sim-test-" + name + "-" + std::to_string(::getpid()));
  fs::remove_all(p);
  return p.string();
}

std::string read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

SimReport simulate(const std::string& dir, const std::string& scenario, std::uint64_t seed, double duration,
                   const std::string& lidar = "") {
  SimOptions o;
  o.scenario = scenario;
  o.seed = seed;
  o.duration = duration;
  o.lidar = lidar;
  o.out = dir;
  return run_simulation(o);
}

TEST(Simulator, SameSeedGivesTheSameBytesAndAnotherSeedDifferentOnes) {
  const std::string a = temp_dir("a"), b = temp_dir("b"), c = temp_dir("c");
  ASSERT_EQ(simulate(a, "urban", 7, 1.5).error, "");
  ASSERT_EQ(simulate(b, "urban", 7, 1.5).error, "");
  ASSERT_EQ(simulate(c, "urban", 8, 1.5).error, "");
  int files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(a)) {
    if (!entry.is_regular_file()) continue;
    const fs::path rel = fs::relative(entry.path(), a);
    SCOPED_TRACE(rel.string());
    const std::string bytes = read_all(entry.path());
    EXPECT_FALSE(bytes.empty());
    EXPECT_EQ(bytes, read_all(fs::path(b) / rel));
    ++files;
  }
  EXPECT_GE(files, 14);  // recording (manifest, pcap, can, 2 serial), world.osm, truth/*
  for (const char* f : {"udp.pcap", "can.log", "serial/gps.log", "serial/imu.log", "world.osm"}) {
    EXPECT_NE(read_all(fs::path(a) / f), read_all(fs::path(c) / f)) << f;
  }
  fs::remove_all(a);
  fs::remove_all(b);
  fs::remove_all(c);
}

struct RangeStats {
  int points = 0;
  double mean = 0.0;
  double std = 0.0;
  double within_5_sigma = 0.0;
  int ground = 0;
  int objects = 0;
};

// Decodes the simulated lidar with the project's decoder and measures each
// point's range against the noise-free surface along the same laser ray.
RangeStats range_error(const std::string& dir, const std::string& scenario_name, std::uint64_t seed,
                       velodyne::Model model, const std::string& calibration_file) {
  const Scenario s = *load_scenario(scenario_name).scenario;
  const RoadNetwork roads = *build_roads(s, seed).roads;
  const auto world = World::build(s, roads, seed);
  const double duration = 0.6;
  const Trajectory traj = drive(s, roads, *world, duration, seed);
  const velodyne::Calibration cal =
      *velodyne::load_calibration(test::shared_data("velodyne/calibration/" + calibration_file)).calibration;
  const auto decoder = std::move(*velodyne::PacketDecoder::create(model, cal).decoder);
  const auto start_us = static_cast<std::uint32_t>((s.start_utc_ns / 1000) % 3'600'000'000LL);

  auto reader = recording::RecordingReader::open(dir);
  EXPECT_TRUE(reader.reader) << reader.error;
  std::vector<velodyne::Point> pts(velodyne::kMaxPointsPerPacket);
  std::vector<double> errors;
  RangeStats stats;
  while (auto e = reader.reader->next()) {
    if (e->payload.size() != velodyne::kDataPacketSize) continue;
    const velodyne::PacketInfo info = decoder.decode(e->payload, pts);
    EXPECT_EQ(info.error, velodyne::PacketError::none);
    const double t_packet = static_cast<double>(info.timestamp_us - start_us) * 1e-6;
    for (int i = 0; i < info.points; ++i) {
      const velodyne::Point& p = pts[static_cast<std::size_t>(i)];
      const double t = t_packet + static_cast<double>(p.time);
      const PoseSample pose = traj.at(t);
      const Eigen::Matrix3d R = rotation(pose.roll, pose.pitch, pose.yaw);
      const Vec3 sensor = pose.p + R * s.robot.lidar_mount;
      // The laser's ray at this firing, from the decoder's own geometry.
      double a = (static_cast<double>(p.azimuth) + cal.lasers[p.laser].rot_correction) * 18000.0 / std::numbers::pi;
      a = std::fmod(a + 36000.0, 36000.0);
      const velodyne::Point p0 = decoder.point_of(p.laser, static_cast<float>(a), 0, 0);
      const velodyne::Point p1 = decoder.point_of(p.laser, static_cast<float>(a), 20000, 0);
      const Vec3 d = Vec3(p1.x - p0.x, p1.y - p0.y, p1.z - p0.z).normalized();
      const Vec3 o = Vec3(p0.x, p0.y, p0.z) - d * static_cast<double>(p0.distance);
      const Hit truth = world->cast(sensor + R * o, R * d, 0.5, 200.0, 0);
      if (!truth.hit || truth.through_medium || truth.kind == HitKind::canopy || truth.kind == HitKind::medium) continue;
      const double measured = (Vec3(p.x, p.y, p.z) - o).dot(d);
      const double err = measured - truth.distance;
      if (std::abs(err) > 1.0) continue;  // grass or leaves the noise-free cast ignores
      errors.push_back(err);
      (truth.kind == HitKind::ground ? stats.ground : stats.objects) += 1;
    }
  }
  double sum = 0, sum2 = 0;
  for (double e : errors) sum += e;
  stats.points = static_cast<int>(errors.size());
  stats.mean = sum / stats.points;
  for (double e : errors) sum2 += (e - stats.mean) * (e - stats.mean);
  stats.std = std::sqrt(sum2 / stats.points);
  int inside = 0;
  for (double e : errors) inside += std::abs(e - stats.mean) < 5 * 0.02 ? 1 : 0;
  stats.within_5_sigma = static_cast<double>(inside) / stats.points;
  return stats;
}

void expect_on_surfaces(const RangeStats& st, const char* model) {
  std::printf("[ range error %s ] %d points (%d ground, %d objects): mean %.2f mm, std %.2f mm (configured 20 mm); "
              "%.3f %% within 5 sigma\n",
              model, st.points, st.ground, st.objects, st.mean * 1e3, st.std * 1e3, st.within_5_sigma * 100.0);
  EXPECT_GT(st.points, 10000);
  EXPECT_GT(st.objects, 100);
  EXPECT_LT(std::abs(st.mean), 0.003);
  // Configured 20 mm plus the 2 mm distance quantisation.
  EXPECT_GT(st.std, 0.018);
  EXPECT_LT(st.std, 0.023);
  EXPECT_GT(st.within_5_sigma, 0.995);
}

TEST(Simulator, Vlp16PointsLieOnTheIntendedSurfaces) {
  const std::string dir = temp_dir("vlp16");
  ASSERT_EQ(simulate(dir, "urban", 3, 0.6, "VLP-16").error, "");
  expect_on_surfaces(range_error(dir, "urban", 3, velodyne::Model::vlp16, "ros_velodyne_VLP16db.yaml"), "VLP-16");
  fs::remove_all(dir);
}

TEST(Simulator, Hdl64ePointsLieOnTheIntendedSurfaces) {
  const std::string dir = temp_dir("hdl64");
  ASSERT_EQ(simulate(dir, "urban", 3, 0.6, "HDL-64E").error, "");
  expect_on_surfaces(range_error(dir, "urban", 3, velodyne::Model::hdl64e, "ros_velodyne_64e_s2.1-sztaki.yaml"),
                     "HDL-64E");
  fs::remove_all(dir);
}

TEST(Simulator, Vlp32cPointsLieOnTheIntendedSurfaces) {
  // Lasers fired in pairs, each with its own azimuth offset (the VeloView table).
  const std::string dir = temp_dir("vlp32c");
  ASSERT_EQ(simulate(dir, "urban", 3, 0.6, "VLP-32C").error, "");
  expect_on_surfaces(range_error(dir, "urban", 3, velodyne::Model::vlp32c, "ros_velodyne_VeloView-VLP-32C.yaml"),
                     "VLP-32C");
  fs::remove_all(dir);
}

TEST(Simulator, NmeaPassesTheGpsParserAndFollowsTheRobot) {
  const std::string dir = temp_dir("nmea");
  const SimReport r = simulate(dir, "forest-track", 5, 20.0);
  ASSERT_EQ(r.error, "");
  const Scenario s = *load_scenario("forest-track").scenario;
  const GeoFrame geo(s.origin_lat, s.origin_lon);
  const RoadNetwork roads = *build_roads(s, 5).roads;
  const auto world = World::build(s, roads, 5);
  const Trajectory traj = drive(s, roads, *world, 20.0, 5);

  auto reader = recording::RecordingReader::open(dir);
  ASSERT_TRUE(reader.reader) << reader.error;
  int counts[8] = {};
  double max_error = 0.0, sum_error = 0.0;
  int fixes = 0;
  while (auto e = reader.reader->next()) {
    if (reader.reader->streams()[static_cast<std::size_t>(e->stream)].name != "gps") continue;
    const std::string_view line(reinterpret_cast<const char*>(e->payload.data()), e->payload.size());
    gps::NmeaSentence n;
    ASSERT_EQ(gps::parse_nmea(line, n), gps::NmeaError::none) << line;
    EXPECT_EQ(std::string(n.talker.data()), "GP");
    ++counts[static_cast<int>(n.type)];
    if (n.type == gps::SentenceType::gga) {
      EXPECT_EQ(n.gga.quality, 1);
      const Vec2 p = geo.from_latlon(n.gga.lat, n.gga.lon);
      const double t = std::fmod(n.gga.time - std::fmod(static_cast<double>(s.start_utc_ns) * 1e-9, 86400.0) + 86400.0, 86400.0);
      const Vec2 truth = traj.at(t).p.head<2>();
      const double err = (p - truth).norm();
      max_error = std::max(max_error, err);
      sum_error += err;
      ++fixes;
    }
    if (n.type == gps::SentenceType::rmc) {
      EXPECT_TRUE(n.rmc.valid);
      EXPECT_EQ(n.rmc.year, 2026);
      EXPECT_EQ(n.rmc.month, 6);
    }
    if (n.type == gps::SentenceType::gst) {
      EXPECT_GT(n.gst.sigma_lat, 1.0);
    }
  }
  EXPECT_EQ(counts[static_cast<int>(gps::SentenceType::gga)], 201);
  EXPECT_EQ(counts[static_cast<int>(gps::SentenceType::rmc)], 201);
  EXPECT_EQ(counts[static_cast<int>(gps::SentenceType::gst)], 201);
  EXPECT_EQ(counts[static_cast<int>(gps::SentenceType::vtg)], 201);
  // A wandering bias of a few metres plus noise: off, but not wildly.
  std::printf("[ gps ] %d fixes: mean error %.2f m, max %.2f m\n", fixes, sum_error / fixes, max_error);
  EXPECT_GT(sum_error / fixes, 0.3);
  EXPECT_LT(max_error, 25.0);
  fs::remove_all(dir);
}

TEST(Simulator, CanLogDecodesWithTheShippedDbcIntoTheWheelSpeeds) {
  const std::string dir = temp_dir("can");
  ASSERT_EQ(simulate(dir, "urban", 2, 15.0).error, "");
  // The DBC file in the repository, not the copy built into the binary.
  auto dbc = can::load_dbc("board/sim/trailnav-robot.dbc");
  ASSERT_TRUE(dbc.dbc) << dbc.error;
  EXPECT_EQ(std::string(robot_dbc_text()), read_all("board/sim/trailnav-robot.dbc"));
  const can::DbcMessage& speeds = *dbc.dbc->message("WHEEL_SPEEDS");
  const can::DbcMessage& ticks = *dbc.dbc->message("WHEEL_TICKS");

  const Scenario s = *load_scenario("urban").scenario;
  const RoadNetwork roads = *build_roads(s, 2).roads;
  const auto world = World::build(s, roads, 2);
  const Trajectory traj = drive(s, roads, *world, 15.0, 2);

  auto reader = recording::RecordingReader::open(dir);
  ASSERT_TRUE(reader.reader) << reader.error;
  int frames = 0, moving = 0;
  double last_ticks = -1;
  while (auto e = reader.reader->next()) {
    if (e->kind != recording::StreamKind::can) continue;
    const recording::CanFrame& f = *e->can;
    const std::span<const std::uint8_t> data(f.data.data(), f.length);
    const double t = static_cast<double>(f.time_ns - s.start_utc_ns) * 1e-9;
    if (f.id == speeds.id) {
      double left = 0, right = 0;
      ASSERT_EQ(can::decode_signal(*speeds.signal("SpeedLeft"), data, left), can::SignalError::none);
      ASSERT_EQ(can::decode_signal(*speeds.signal("SpeedRight"), data, right), can::SignalError::none);
      const PoseSample p = traj.at(std::round(t * s.wheels.rate) / s.wheels.rate);
      // Scale error exactly, slip only ever adds speed on loose ground.
      const double tol = 0.0006 + 4 * s.wheels.slip * std::abs(p.v_left);
      EXPECT_NEAR(left, p.v_left * s.wheels.scale_left, tol) << "t = " << t;
      EXPECT_NEAR(right, p.v_right * s.wheels.scale_right, 0.0006 + 4 * s.wheels.slip * std::abs(p.v_right));
      moving += p.v > 0.5 ? 1 : 0;
      ++frames;
    } else if (f.id == ticks.id) {
      double tl = 0;
      ASSERT_EQ(can::decode_signal(*ticks.signal("TicksLeft"), data, tl), can::SignalError::none);
      EXPECT_GE(tl, last_ticks);
      last_ticks = tl;
    } else {
      ADD_FAILURE() << "unexpected CAN id " << f.id;
    }
  }
  EXPECT_EQ(frames, 751);
  EXPECT_GT(moving, 400);
  // About 1.01 x the distance driven, in ticks of 0.5 mm.
  EXPECT_NEAR(last_ticks / 2000.0, traj.at(15.0).arc * 1.01, 0.6);
  fs::remove_all(dir);
}

TEST(Simulator, XsensMessagesDecodeToTheTrueAttitude) {
  const std::string dir = temp_dir("imu");
  ASSERT_EQ(simulate(dir, "forest-track", 4, 20.0).error, "");
  // Truth: time and attitude at 100 Hz.
  std::vector<std::array<double, 4>> truth;  // utc s, roll, pitch, yaw
  {
    std::ifstream in(dir + "/truth/trajectory.csv");
    std::string line;
    std::getline(in, line);
    while (std::getline(in, line)) {
      double t = 0, x = 0, y = 0, z = 0, roll = 0, pitch = 0, yaw = 0;
      long long utc = 0;
      ASSERT_EQ(std::sscanf(line.c_str(), "%lf,%lld,%lf,%lf,%lf,%lf,%lf,%lf", &t, &utc, &x, &y, &z, &roll, &pitch, &yaw), 8);
      truth.push_back({static_cast<double>(utc) * 1e-9, roll, pitch, yaw});
    }
  }
  auto reader = recording::RecordingReader::open(dir);
  ASSERT_TRUE(reader.reader) << reader.error;
  imu::XbusFramer framer;
  imu::AttitudeOptions filter_only;
  filter_only.use_device_orientation = false;
  imu::AttitudeFilter filter(filter_only);
  int messages = 0;
  std::uint16_t last_counter = 0;
  double device_err = 0.0, filter_sq = 0.0;
  int filter_n = 0;
  std::uint32_t first_fine = 0;
  while (auto e = reader.reader->next()) {
    if (reader.reader->streams()[static_cast<std::size_t>(e->stream)].name != "imu") continue;
    framer.feed(e->payload, [&](const imu::XbusMessage& m) {
      ASSERT_EQ(m.mid, imu::mid::kMtData2);
      imu::ImuSample s;
      ASSERT_EQ(imu::decode_mtdata2(m.payload, s), imu::XsensError::none);
      ASSERT_EQ(s.fields, imu::kPacketCounter | imu::kSampleTimeFine | imu::kOrientation | imu::kAcceleration |
                              imu::kRateOfTurn | imu::kStatusWord);
      if (messages > 0) {
        EXPECT_EQ(s.packet_counter, static_cast<std::uint16_t>(last_counter + 1));
      } else {
        first_fine = s.sample_time_fine;
      }
      last_counter = s.packet_counter;
      // The sample's truth: the simulator samples at 100 Hz from the start.
      const auto k = static_cast<std::size_t>(std::lround((s.sample_time_fine - first_fine) * 1e-4 * 100.0));
      ASSERT_LT(k, truth.size());
      const auto& tr = truth[k];
      const Eigen::Quaterniond q(s.orientation[0], s.orientation[1], s.orientation[2], s.orientation[3]);
      const Eigen::Matrix3d r = q.toRotationMatrix();
      device_err = std::max({device_err, std::abs(std::atan2(r(2, 1), r(2, 2)) - tr[1]), std::abs(-std::asin(r(2, 0)) - tr[2])});
      const imu::Attitude& a = filter.update(s);
      if (k >= 1000) {  // after 10 s
        filter_sq += (a.roll - tr[1]) * (a.roll - tr[1]) + (a.pitch - tr[2]) * (a.pitch - tr[2]);
        filter_n += 2;
      }
      ++messages;
    });
  }
  EXPECT_EQ(messages, 2001);
  EXPECT_EQ(framer.counters().bad_checksum, 0u);
  EXPECT_LT(device_err, 1e-5);  // float32 quaternion
  // The complementary filter from the simulated MEMS gyro (bias 3 mrad/s) and
  // accelerometer (bias 0.05 m/s^2) on a bumpy forest track.
  const double rms_deg = std::sqrt(filter_sq / filter_n) * 180.0 / M_PI;
  std::printf("filter roll/pitch RMS error against truth over the last 10 s: %.2f deg\n", rms_deg);
  EXPECT_LT(rms_deg, 1.0);
  fs::remove_all(dir);
}

TEST(Simulator, ScenarioErrorsNameFileLineAndKey) {
  auto r = parse_scenario("format: trailnav-scenario\nversion: 1\nname: x\norigin: {lat: 48, lon: 7}\n"
                          "world: {extent: [0, 0, 10, 10]}\ntrails:\n  - name: a\n    points: [[0, 0], [5]]\n"
                          "route: [{trail: a}]\n",
                          "bad.yaml");
  ASSERT_FALSE(r.scenario);
  EXPECT_NE(r.error.find("bad.yaml:8"), std::string::npos) << r.error;
  EXPECT_NE(r.error.find("points[1]"), std::string::npos) << r.error;
  r = parse_scenario("format: trailnav-scenario\nversion: 1\nname: x\norigin: {lat: 48, lon: 7}\n"
                     "world: {extent: [0, 0, 10, 10], colour: red}\ntrails:\n  - name: a\n    points: [[0, 0], [5, 0]]\n"
                     "route: [{trail: b}]\n",
                     "bad.yaml");
  ASSERT_FALSE(r.scenario);
  EXPECT_NE(r.error.find("colour"), std::string::npos) << r.error;
  EXPECT_FALSE(load_scenario("no-such-scenario").scenario);
  SimOptions o;
  o.scenario = "urban";
  o.lidar = "VLS-9000";
  o.out = temp_dir("bad");
  EXPECT_NE(run_simulation(o).error.find("VLS-9000"), std::string::npos);
}

// Which side returns show their face (truth.hpp): a ray square on to a
// box's side well below its top does; one that clips the top edge, or one
// that runs along the side, hits it and shows nothing a detector could see.
TEST(Simulator, SideReturnsShowTheirFaceBelowTheTopEdgeAndNotGrazing) {
  const auto parsed = parse_scenario(
      "format: trailnav-scenario\nversion: 1\nname: box\norigin: {lat: 48, lon: 7}\n"
      "world: {extent: [-5, -10, 20, 10], background: street}\n"
      "trails:\n  - name: a\n    class: street\n    points: [[-4, 8], [19, 8]]\n"
      "obstacles:\n  - {type: box, name: b, center: [10, 0], size: [2, 1, 0.5], yaw: 0}\n"
      "route: [{trail: a}]\n",
      "box.yaml");
  ASSERT_TRUE(parsed.scenario) << parsed.error;
  const RoadNetwork roads = *build_roads(*parsed.scenario, 1).roads;
  const auto world = World::build(*parsed.scenario, roads, 1);
  // The box stands on the lowest ground under its corners and centre.
  double base = world->ground(10, 0);
  for (double x : {9.0, 11.0}) {
    for (double y : {-0.5, 0.5}) base = std::min(base, world->ground(x, y));
  }
  const double top = base + 0.5;
  const auto cast = [&](const Vec3& at, const Vec3& dir) {
    const Vec3 d = dir.normalized();
    return world->cast(at - 8.0 * d, d, 0.5, 50.0, 7);
  };
  constexpr double kDeg = std::numbers::pi / 180.0;

  // Square on to the west side, 25 cm below the top: shown.
  Hit h = cast({9.0, 0.0, top - 0.25}, {1, 0, 0});
  ASSERT_TRUE(h.hit);
  EXPECT_EQ(h.kind, HitKind::object);
  EXPECT_TRUE(h.side);
  EXPECT_NEAR(h.distance, 8.0, 1e-6);
  EXPECT_NEAR(h.below_top, 0.25, 1e-6);
  EXPECT_TRUE(side_shown(h));

  // The same side 3 cm below the top edge: a side hit that shows 3 cm of face.
  h = cast({9.0, 0.2, top - 0.03}, {1, 0, 0});
  ASSERT_TRUE(h.hit && h.side);
  EXPECT_NEAR(h.below_top, 0.03, 1e-6);
  EXPECT_FALSE(side_shown(h));

  // The south side, met at 5 degrees (the ray passes south of the west side's
  // corner and runs along the south side): a side hit, not shown. At 30
  // degrees: shown.
  for (const double deg : {5.0, 30.0}) {
    h = cast({10.5, -0.5, top - 0.25}, {std::cos(deg * kDeg), std::sin(deg * kDeg), 0});
    ASSERT_TRUE(h.hit && h.side) << deg;
    EXPECT_NEAR(h.distance, 8.0, 1e-6) << deg;
    EXPECT_NEAR(h.cos_incidence, std::sin(deg * kDeg), 1e-9) << deg;
    EXPECT_EQ(side_shown(h), deg > kSideSightingAngle) << deg;
  }

  // From above onto the top: no side at all.
  h = cast({10.0, 0.0, top}, {1, 0, -1});
  ASSERT_TRUE(h.hit);
  EXPECT_EQ(h.kind, HitKind::object);
  EXPECT_FALSE(h.side);
  EXPECT_FALSE(side_shown(h));
}

TEST(Simulator, EveryBuiltInScenarioBuildsWithJunctionsWhereTheRouteTurns) {
  for (const std::string& name : builtin_scenario_names()) {
    SCOPED_TRACE(name);
    const auto loaded = load_scenario(name);
    ASSERT_TRUE(loaded.scenario) << loaded.error;
    const auto roads = build_roads(*loaded.scenario, 1);
    ASSERT_TRUE(roads.roads) << roads.error;
    EXPECT_GT(roads.roads->route.length(), 40.0);
    EXPECT_GE(roads.roads->junctions.size(), loaded.scenario->route.size() - 1);
    EXPECT_EQ(roads.roads->osm.size(), loaded.scenario->trails.size());
  }
  const auto j = load_scenario("junctions");
  const auto roads = *build_roads(*j.scenario, 1).roads;
  EXPECT_EQ(roads.junctions.size(), 6u);
  // The mapped junctions carry the configured shifts along the driving direction.
  int checked = 0;
  for (const JunctionError& e : j.scenario->junction_errors) {
    for (const Junction& jn : roads.junctions) {
      const std::string& a = roads.trails[static_cast<std::size_t>(jn.a)].spec->name;
      const std::string& b = roads.trails[static_cast<std::size_t>(jn.b)].spec->name;
      if (!((a == e.a && b == e.b) || (a == e.b && b == e.a))) continue;
      const TrailGeometry& along = roads.trails[static_cast<std::size_t>(a == e.a ? jn.a : jn.b)];
      const double arc = a == e.a ? jn.arc_a : jn.arc_b;
      // The lateral map error is perpendicular to the trail; the shift is along it.
      EXPECT_NEAR((jn.mapped - jn.point).dot(along.centre.tangent(arc)), e.shift, 0.8) << e.a << "/" << e.b;
      ++checked;
    }
  }
  EXPECT_EQ(checked, 6);
}

}  // namespace

namespace {

// The simulated camera (camera.hpp): frames rendered from a pose of the
// urban drive, the same bytes for the same seed; the sky above the horizon
// and the street below it where a level camera puts them; winter brighter
// (snow, an overcast sky) and flatter than summer; and the recording's
// image stream holds every frame, said to be simulated.
TEST(SimulatedCamera, SkyAboveStreetBelowAndWinterIsAnotherSeason) {
  const auto loaded = load_scenario("urban");
  ASSERT_TRUE(loaded.scenario) << loaded.error;
  const Scenario& s = *loaded.scenario;
  auto built = build_roads(s, 1);
  ASSERT_TRUE(built.roads) << built.error;
  const auto world = World::build(s, *built.roads, 1);
  const Trajectory traj = drive(s, *built.roads, *world, 20.0, 1);
  CameraSpec spec;
  spec.pitch_deg = 0.0;
  spec.noise = 0.0;
  const auto frame = [&](Season season, double t, std::uint64_t seed) {
    CameraRenderer r(*world, spec, season, seed);
    std::vector<std::uint8_t> px(static_cast<std::size_t>(spec.width * spec.height));
    r.render(traj.at(t), 7, px);
    return px;
  };
  const std::vector<std::uint8_t> summer = frame(Season::summer, 10.0, 1), winter = frame(Season::winter, 10.0, 1);
  EXPECT_EQ(summer, frame(Season::summer, 10.0, 1));
  EXPECT_NE(summer, frame(Season::summer, 12.0, 1));
  const auto mean_rows = [&](const std::vector<std::uint8_t>& px, int from, int to) {
    double sum = 0.0;
    for (int v = from; v < to; ++v)
      for (int u = 0; u < spec.width; ++u) sum += px[static_cast<std::size_t>(v * spec.width + u)];
    return sum / ((to - from) * spec.width);
  };
  const auto spread = [&](const std::vector<std::uint8_t>& px) {
    const double m = mean_rows(px, 0, spec.height);
    double sq = 0.0;
    for (std::uint8_t p : px) sq += (p - m) * (p - m);
    return std::sqrt(sq / static_cast<double>(px.size()));
  };
  // The top rows are sky (brighter than the street at the bottom, which the
  // urban drive follows).
  EXPECT_GT(mean_rows(summer, 0, 6), mean_rows(summer, spec.height - 6, spec.height) + 40.0);
  EXPECT_GT(mean_rows(winter, spec.height / 2, spec.height), mean_rows(summer, spec.height / 2, spec.height) + 20.0);
  EXPECT_LT(spread(winter), spread(summer));
  std::printf("[ camera ] summer mean %.0f, spread %.1f; winter mean %.0f, spread %.1f\n", mean_rows(summer, 0, spec.height),
              spread(summer), mean_rows(winter, 0, spec.height), spread(winter));

  const std::string dir = temp_dir("camera");
  SimOptions o;
  o.scenario = "urban";
  o.duration = 4.0;
  o.lidar_packets = false;
  o.camera = true;
  o.season = Season::winter;
  o.out = dir;
  const SimReport r = run_simulation(o);
  ASSERT_TRUE(r.error.empty()) << r.error;
  EXPECT_EQ(r.camera_frames, 40u);  // 10 Hz, half a period late, for 4 s
  auto opened = recording::RecordingReader::open(dir);
  ASSERT_TRUE(opened.reader) << opened.error;
  const int cam = opened.reader->stream_index("camera", recording::StreamKind::image);
  ASSERT_GE(cam, 0);
  EXPECT_NE(opened.reader->streams()[static_cast<std::size_t>(cam)].description.find("simulated camera, winter"), std::string::npos);
  std::size_t images = 0;
  while (auto e = opened.reader->next()) {
    if (e->kind != recording::StreamKind::image) continue;
    EXPECT_EQ(e->image_width, 128);
    EXPECT_EQ(e->payload.size(), 128u * 64u);
    ++images;
  }
  EXPECT_EQ(images, 40u);
  fs::remove_all(dir);
}

}  // namespace
