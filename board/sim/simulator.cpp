#include "simulator.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>

#include "motion.hpp"
#include "random.hpp"
#include "roads.hpp"
#include "scenario.hpp"
#include "sensors.hpp"
#include "sim_builtin.hpp"
#include "truth.hpp"
#include "trailnav/drivers/can/dbc.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/drivers/velodyne/calibration.hpp"
#include "trailnav/drivers/velodyne/decoder.hpp"
#include "world.hpp"

namespace trailnav::sim {
namespace {

namespace fs = std::filesystem;
namespace vel = trailnav::velodyne;
using Clock = std::chrono::steady_clock;

constexpr double kPi = std::numbers::pi;
constexpr double kGravity = 9.80665;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace

std::string default_calibration_file(vel::Model model) {
  const char* name = nullptr;
  switch (model) {
    case vel::Model::vlp16: name = "ros_velodyne_VLP16db.yaml"; break;
    case vel::Model::vlp16_hires: name = "ros_velodyne_VLP16_hires_db.yaml"; break;
    case vel::Model::vlp32c: name = "ros_velodyne_VeloView-VLP-32C.yaml"; break;
    case vel::Model::hdl32e: name = "ros_velodyne_32db.yaml"; break;
    case vel::Model::hdl64e: name = "ros_velodyne_64e_s2.1-sztaki.yaml"; break;
  }
  for (const std::string& base : {std::string("../shared/data/velodyne/calibration/"),
                                 std::string(TRAILNAV_SOURCE_DIR) + "/../shared/data/velodyne/calibration/"}) {
    if (fs::exists(base + name)) return base + name;
  }
  return "";
}

namespace {

// The lidar: packets of the chosen model, ray-cast against the world at each
// firing's time and pose.
class LidarSim {
 public:
  LidarSim(const vel::PacketDecoder& decoder, const Scenario& s, const World& world, const Trajectory& traj,
           std::uint64_t seed)
      : d_(decoder), s_(s), world_(world), traj_(traj), seed_(seed), info_(decoder.model()) {
    is64_ = info_.model == vel::Model::hdl64e;
    group_size_ = is64_ ? 2 : 1;
    groups_ = vel::kBlocksPerPacket / group_size_;
    packet_period_us_ = groups_ * info_.group_period_us;
    // Azimuth rate in hundredths of a degree per microsecond.
    rate_ = s.lidar.rpm * 36000.0 / 60e6;
    phase0_ = 36000.0 * unit(hash(seed, 0x1D1D));
    const auto lasers = static_cast<int>(decoder.calibration().lasers.size());
    for (int l = 0; l < lasers; ++l) {
      // Each laser's ray at azimuth 0 in the sensor frame, from the decoder itself.
      const vel::Point p0 = d_.point_of(l, 0.0f, 0, 0);
      const vel::Point p1 = d_.point_of(l, 0.0f, 10000, 0);
      Vec3 dir(p1.x - p0.x, p1.y - p0.y, p1.z - p0.z);
      dir.normalize();
      const Vec3 origin = Vec3(p0.x, p0.y, p0.z) - dir * static_cast<double>(p0.distance);
      dir0_.push_back(dir);
      origin0_.push_back(origin);
      dist_correction_.push_back(static_cast<double>(p0.distance));
      const auto& c = decoder.calibration().lasers[static_cast<std::size_t>(l)];
      two_pt_.push_back(c.two_pt_correction);
      intensity_corrected_.push_back(c.focal_slope != 0.0 || c.min_intensity != 0 || c.max_intensity != 255);
    }
    mount_ = s.robot.lidar_mount;
    sighted_.any.assign(static_cast<std::size_t>(world.width()) * static_cast<std::size_t>(world.height()), 0);
    sighted_.side_hit.assign(sighted_.any.size(), 0);
    sighted_.side.assign(sighted_.any.size(), 0);
    sighted_.returns.assign(sighted_.any.size(), 0);
  }

  double packet_start_us(std::uint64_t i) const { return static_cast<double>(i) * packet_period_us_; }
  double packet_period_us() const { return packet_period_us_; }

  // Builds packet i; returns its first firing's time in seconds.
  void build(std::uint64_t index, std::int64_t start_utc_ns, std::array<std::uint8_t, vel::kDataPacketSize>& pkt) {
    pkt.fill(0);
    const double t0 = packet_start_us(index);
    std::array<int, vel::kBlocksPerPacket> az{};
    for (int g = 0; g < groups_; ++g) {
      const double a = phase0_ + rate_ * (t0 + g * info_.group_period_us);
      az[static_cast<std::size_t>(g)] = static_cast<int>(std::llround(a)) % 36000;
    }
    // The decoder's view of each group's advance.
    std::array<int, vel::kBlocksPerPacket> gap{};
    for (int g = 0; g < groups_; ++g) {
      int diff = g > 0 ? gap[static_cast<std::size_t>(g - 1)] : 0;
      if (g + 1 < groups_) {
        diff = az[static_cast<std::size_t>(g + 1)] - az[static_cast<std::size_t>(g)];
        if (diff < 0) diff += 36000;
      }
      gap[static_cast<std::size_t>(g)] = diff;
    }
    const double rmin = s_.lidar.min_range;
    const double rmax = s_.lidar.max_range;
    const double res = d_.distance_resolution();
    for (int g = 0; g < groups_; ++g) {
      const double tg_us = t0 + g * info_.group_period_us;
      const PoseSample pose = traj_.at((tg_us + 0.5 * info_.group_period_us) * 1e-6);
      const Eigen::Matrix3d R = rotation(pose.roll, pose.pitch, pose.yaw);
      const Vec3 sensor = pose.p + R * mount_;
      for (int blk = 0; blk < group_size_; ++blk) {
        const int b = g * group_size_ + blk;
        std::uint8_t* block = pkt.data() + static_cast<std::size_t>(b) * vel::kBlockSize;
        const bool lower = is64_ && blk == 1;
        const std::uint16_t flag = lower ? vel::kLowerBlockFlag : vel::kUpperBlockFlag;
        block[0] = static_cast<std::uint8_t>(flag);
        block[1] = static_cast<std::uint8_t>(flag >> 8);
        block[2] = static_cast<std::uint8_t>(az[static_cast<std::size_t>(g)]);
        block[3] = static_cast<std::uint8_t>(az[static_cast<std::size_t>(g)] >> 8);
        const int per_sequence = vel::kReturnsPerBlock / info_.sequences_per_block;
        for (int k = 0; k < vel::kReturnsPerBlock; ++k) {
          const int laser = (lower ? 32 : 0) + k % per_sequence;
          const auto lz = static_cast<std::size_t>(laser);
          const float t_in = d_.firing_offset_us(k);
          float a = static_cast<float>(az[static_cast<std::size_t>(g)]) +
                    static_cast<float>(gap[static_cast<std::size_t>(g)]) * (t_in / static_cast<float>(info_.group_period_us));
          if (a >= 36000.0f) a -= 36000.0f;
          // The laser's ray at this azimuth in the sensor frame: origin os, unit direction ds, and
          // `step` metres along it per distance count.
          Vec3 ds, os;
          double step = res;
          if (two_pt_[lz]) {
            // The HDL-64E's two-point correction makes the decoded point an affine function of the
            // raw distance whose line depends on the azimuth: take it from the decoder.
            const vel::Point p0 = d_.point_of(laser, a, 0, 0);
            const vel::Point p1 = d_.point_of(laser, a, 10000, 0);
            const Vec3 v = (Vec3(p1.x, p1.y, p1.z) - Vec3(p0.x, p0.y, p0.z)) / 10000.0;
            step = v.norm();
            ds = v / step;
            os = Vec3(p0.x, p0.y, p0.z);
          } else {
            const double ar = static_cast<double>(a) * kPi / 18000.0;
            const double ca = std::cos(ar), sa = std::sin(ar);
            // Clockwise rotation by the azimuth about the sensor's z axis.
            const Vec3& d0 = dir0_[lz];
            const Vec3& o0 = origin0_[lz];
            ds = Vec3(d0.x() * ca + d0.y() * sa, -d0.x() * sa + d0.y() * ca, d0.z());
            os = Vec3(o0.x() * ca + o0.y() * sa, -o0.x() * sa + o0.y() * ca, o0.z()) + ds * dist_correction_[lz];
          }
          // From the zero-count point on: distances are counted from there.
          const std::uint64_t key = hash(seed_, index, static_cast<std::uint64_t>(b * 32 + k));
          const Hit hit = world_.cast(sensor + R * os, R * ds, std::max(0.0, rmin - dist_correction_[lz]), rmax, key);
          ++rays_;
          if (!hit.hit || unit(hash(key, 0xD0)) < s_.lidar.dropout) continue;
          const double range = hit.distance + s_.lidar.range_noise * gaussian(hash(key, 0xD1));
          const double raw = std::nearbyint(range / step);
          if (raw < 1.0 || raw > 65535.0) continue;
          const auto r16 = static_cast<std::uint16_t>(raw);
          {
            // Every return, whatever it hit, shows its pixel to the lidar.
            const Vec3 at = sensor + R * (os + ds * hit.distance);
            const auto ms = static_cast<std::uint32_t>(tg_us / 1000.0) + 1;
            if (const std::ptrdiff_t px = world_.pixel(at.x(), at.y()); px >= 0) {
              std::uint32_t& f = sighted_.returns[static_cast<std::size_t>(px)];
              if (f == 0 || ms < f) f = ms;
            }
          }
          if (hit.kind == HitKind::object || hit.kind == HitKind::ground) {
            const auto ms = static_cast<std::uint32_t>(tg_us / 1000.0) + 1;
            const auto mark = [&](std::vector<std::uint32_t>& first, const Vec3& at) {
              const std::ptrdiff_t px = world_.pixel(at.x(), at.y());
              if (px < 0 || world_.obstacle_raster()[static_cast<std::size_t>(px)] !=
                                static_cast<std::uint8_t>(ObstacleTruth::obstacle)) {
                return;
              }
              std::uint32_t& f = first[static_cast<std::size_t>(px)];
              if (f == 0 || ms < f) f = ms;
            };
            const Vec3 at = sensor + R * (os + ds * hit.distance);
            mark(sighted_.any, at);
            if (hit.kind == HitKind::object && hit.side) {
              // A side's hit lies on the footprint's edge: the pixel just
              // inside the face is the one seen.
              const Vec3 in = at + R * ds * 0.03;
              mark(sighted_.any, in);
              if (hit.distance <= kSideSightingRange) {
                mark(sighted_.side_hit, in);
                if (side_shown(hit)) mark(sighted_.side, in);
              }
            }
          }
          double intensity = hit.reflectivity * (0.55 + 0.45 * hit.cos_incidence) + 2.0 * gaussian(hash(key, 0xD2));
          if (intensity_corrected_[lz]) {
            const vel::Point p = d_.point_of(laser, a, r16, 128);
            intensity -= static_cast<double>(p.intensity) - 128.0;
          }
          const auto i8 = static_cast<std::uint8_t>(std::clamp(std::lround(intensity), 0L, 255L));
          std::uint8_t* ret = block + 4 + static_cast<std::size_t>(k) * 3;
          ret[0] = static_cast<std::uint8_t>(r16);
          ret[1] = static_cast<std::uint8_t>(r16 >> 8);
          ret[2] = i8;
          ++returns_;
        }
      }
    }
    const std::int64_t utc_ns = start_utc_ns + static_cast<std::int64_t>(std::llround(t0 * 1000.0));
    const auto us = static_cast<std::uint32_t>((utc_ns / 1000) % 3'600'000'000LL);
    pkt[vel::kTimestampOffset + 0] = static_cast<std::uint8_t>(us);
    pkt[vel::kTimestampOffset + 1] = static_cast<std::uint8_t>(us >> 8);
    pkt[vel::kTimestampOffset + 2] = static_cast<std::uint8_t>(us >> 16);
    pkt[vel::kTimestampOffset + 3] = static_cast<std::uint8_t>(us >> 24);
    if (is64_) {
      // The HDL-64E S2 cycles status bytes: GPS hours, minutes, seconds, ...
      static constexpr char kTypes[] = {'H', 'M', 'S', 'D', 'N', 'Y', 'G', 'T', 'V'};
      const std::int64_t sec = utc_ns / 1'000'000'000;
      const std::uint8_t values[] = {static_cast<std::uint8_t>((sec / 3600) % 24), static_cast<std::uint8_t>((sec / 60) % 60),
                                     static_cast<std::uint8_t>(sec % 60), 21, 6, 26, 0x41, 38, 0x41};
      const auto slot = static_cast<std::size_t>(index % 9);
      pkt[vel::kReturnModeOffset] = static_cast<std::uint8_t>(kTypes[slot]);
      pkt[vel::kProductIdOffset] = values[slot];
    } else {
      pkt[vel::kReturnModeOffset] = 0x37;  // strongest return
      pkt[vel::kProductIdOffset] = info_.product_id;
    }
  }

  std::uint64_t rays() const { return rays_; }
  // Per truth pixel: milliseconds after the start (plus one) of the first
  // return that came from a solid obstacle in it (any part; or a side, shown
  // as truth.hpp says); 0: never seen.
  Sightings take_sightings() { return std::move(sighted_); }
  std::uint64_t returns() const { return returns_; }

 private:
  const vel::PacketDecoder& d_;
  const Scenario& s_;
  const World& world_;
  const Trajectory& traj_;
  std::uint64_t seed_;
  const vel::ModelInfo& info_;
  bool is64_ = false;
  int group_size_ = 1;
  int groups_ = 12;
  double packet_period_us_ = 0.0;
  double rate_ = 0.0;
  double phase0_ = 0.0;
  Sightings sighted_;
  Vec3 mount_{0, 0, 0};
  std::vector<Vec3> dir0_;
  std::vector<Vec3> origin0_;
  std::vector<double> dist_correction_;
  std::vector<bool> two_pt_;
  std::vector<bool> intensity_corrected_;
  std::uint64_t rays_ = 0;
  std::uint64_t returns_ = 0;
};

// GNSS fixes with a wandering bias (first-order Gauss-Markov) and noise.
class GnssSim {
 public:
  GnssSim(const Scenario& s, const Trajectory& traj, const GeoFrame& geo, std::uint64_t seed)
      : s_(s), traj_(traj), geo_(geo), rng_(seed, 0x6A55) {
    bias_ = Vec3(rng_.normal(), rng_.normal(), 0.5 * rng_.normal()) * s.gps.bias_sigma;
  }

  GnssFix fix(int epoch) {
    const double t = epoch / s_.gps.rate;
    const double dt = 1.0 / s_.gps.rate;
    const double a = std::exp(-dt / s_.gps.bias_time);
    const double q = s_.gps.bias_sigma * std::sqrt(1 - a * a);
    if (epoch > 0) bias_ = bias_ * a + Vec3(rng_.normal(), rng_.normal(), 0.5 * rng_.normal()) * q;
    const PoseSample p = traj_.at(t);
    const Vec3 antenna = p.p + rotation(p.roll, p.pitch, p.yaw) * s_.robot.gps_antenna;
    const Vec3 noise(rng_.normal(), rng_.normal(), 1.5 * rng_.normal());
    const Vec3 measured = antenna + bias_ + noise * s_.gps.noise;
    GnssFix f;
    f.utc_ns = s_.start_utc_ns + static_cast<std::int64_t>(std::llround(t * 1e9));
    geo_.to_latlon(measured.x(), measured.y(), f.lat, f.lon);
    f.altitude = s_.origin_alt + measured.z();
    f.speed = std::max(0.0, p.v + 0.03 * rng_.normal());
    double course = 90.0 - (p.yaw - geo_.convergence()) * 180.0 / kPi;
    course = std::fmod(course, 360.0);
    if (course < 0) course += 360.0;
    f.course = course;
    const double sigma = std::hypot(s_.gps.noise, s_.gps.bias_sigma);
    f.sigma_lat = sigma;
    f.sigma_lon = sigma * 1.1;
    f.sigma_alt = sigma * 1.8;
    f.rms = sigma * 0.6;
    f.satellites = 9 + static_cast<int>(4 * unit(hash(static_cast<std::uint64_t>(epoch / 50), 0x5A7)));
    f.hdop = 0.7 + 0.1 * (13 - f.satellites);
    return f;
  }

 private:
  const Scenario& s_;
  const Trajectory& traj_;
  const GeoFrame& geo_;
  Rng rng_;
  Vec3 bias_{0, 0, 0};
};

std::int64_t ns(double seconds) { return static_cast<std::int64_t>(std::llround(seconds * 1e9)); }

}  // namespace

const char* robot_dbc_text() noexcept { return kRobotDbc; }

SimReport run_simulation(const SimOptions& o) {
  const auto t_start = Clock::now();
  SimReport report;
  auto fail = [&](std::string message) {
    report.error = std::move(message);
    return report;
  };

  auto loaded = load_scenario(o.scenario);
  if (!loaded.scenario) return fail(loaded.error);
  Scenario s = std::move(*loaded.scenario);
  report.scenario = s.name;
  if (!o.lidar.empty()) s.lidar.model = o.lidar;
  if (!o.calibration.empty()) s.lidar.calibration = o.calibration;
  const auto model = vel::parse_model(s.lidar.model);
  if (!model) {
    return fail("lidar model '" + s.lidar.model + "' cannot be simulated; choose VLP-16, VLP-16-HiRes, VLP-32C, HDL-32E or HDL-64E");
  }
  report.lidar_model = std::string(vel::model_info(*model).name);
  std::string calib_path = s.lidar.calibration.empty() ? default_calibration_file(*model) : s.lidar.calibration;
  std::optional<vel::Calibration> calibration;
  if (calib_path.empty()) {
    calibration = vel::builtin_calibration(*model);
    if (!calibration) {
      return fail("no calibration for the " + report.lidar_model +
                  ": ../shared/data/velodyne/calibration/ is not here; pass --calibration FILE");
    }
    report.calibration = calibration->source;
  } else {
    auto c = vel::load_calibration(calib_path);
    if (!c.calibration) return fail(c.error);
    calibration = std::move(c.calibration);
    report.calibration = calib_path;
  }
  auto created = vel::PacketDecoder::create(*model, *calibration);
  if (!created.decoder) return fail(created.error);
  const vel::PacketDecoder& decoder = *created.decoder;

  auto dbc = can::parse_dbc(kRobotDbc, "(built-in board/sim/trailnav-robot.dbc)");
  if (!dbc.dbc) return fail(dbc.error);
  const can::DbcMessage* speeds = dbc.dbc->message("WHEEL_SPEEDS");
  const can::DbcMessage* ticks = dbc.dbc->message("WHEEL_TICKS");
  if (!speeds || !ticks) return fail("the built-in robot DBC lacks WHEEL_SPEEDS or WHEEL_TICKS");
  const can::DbcSignal* speed_left = speeds->signal("SpeedLeft");
  const can::DbcSignal* speed_right = speeds->signal("SpeedRight");
  const can::DbcSignal* counter = speeds->signal("Counter");
  const can::DbcSignal* status = speeds->signal("Status");
  const can::DbcSignal* ticks_left = ticks->signal("TicksLeft");
  const can::DbcSignal* ticks_right = ticks->signal("TicksRight");
  if (!speed_left || !speed_right || !counter || !status || !ticks_left || !ticks_right) {
    return fail("the built-in robot DBC lacks a wheel signal (SpeedLeft, SpeedRight, Counter, Status, TicksLeft, TicksRight)");
  }

  auto built = build_roads(s, o.seed);
  if (!built.roads) return fail(built.error);
  const RoadNetwork& roads = *built.roads;
  report.route_length = roads.route.length();
  const auto world = World::build(s, roads, o.seed);
  report.world_seconds = seconds_since(t_start);
  const double duration = o.duration > 0 ? o.duration : s.duration;
  const Trajectory traj = drive(s, roads, *world, duration, o.seed);
  report.sim_seconds = traj.duration();
  const GeoFrame geo(s.origin_lat, s.origin_lon);

  std::error_code ec;
  fs::create_directories(o.out, ec);
  if (ec) return fail("cannot create " + o.out + ": " + ec.message());
  auto made = recording::RecordingWriter::create(o.out, "simulated: scenario " + s.name + ", seed " +
                                                            std::to_string(o.seed) + ", lidar " + report.lidar_model +
                                                            (o.camera ? std::string(", camera (") + season_name(o.season) + ")" : ""));
  if (!made.writer) return fail(made.error);
  recording::RecordingWriter& w = *made.writer;
  const int lidar_stream = w.add_udp_stream("lidar", 2368, report.lidar_model + " data packets");
  const int position_stream = w.add_udp_stream("lidar-position", 8308, report.lidar_model + " position packets");
  const int gps_stream = w.add_serial_stream("gps", s.gps.baud, "NMEA 0183: GGA, RMC, GST, VTG");
  const int imu_stream = w.add_serial_stream("imu", s.imu.baud, "Xsens MT binary, MTData2");
  const int can_stream = w.add_can_stream("wheels", "can0", "wheel odometry, board/sim/trailnav-robot.dbc");
  const int gpio_stream = w.add_gpio_stream("gpio", "emergency stop (line ESTOP, 1: pressed)");
  Status st = Status::ok();
  auto check = [&](Status result) {
    if (st && !result) st = result;
  };

  // GNSS: sentences in one burst per epoch, timed by the serial line's rate.
  GnssSim gnss(s, traj, geo, o.seed);
  std::string last_rmc;
  std::vector<std::string> rmc_by_second;  // the RMC of each whole second, for the lidar's position packets
  const int epochs = static_cast<int>(std::floor(report.sim_seconds * s.gps.rate)) + 1;
  const double byte_time = 10.0 / s.gps.baud;
  for (int e = 0; e < epochs; ++e) {
    const GnssFix f = gnss.fix(e);
    double t = e / s.gps.rate + 0.045;
    for (const std::string& sentence : {nmea_gga(f), nmea_rmc(f), nmea_gst(f), nmea_vtg(f)}) {
      t += static_cast<double>(sentence.size()) * byte_time;
      check(w.write_serial(gps_stream, s.start_utc_ns + ns(t),
                           {reinterpret_cast<const std::uint8_t*>(sentence.data()), sentence.size()}));
      ++report.nmea_sentences;
    }
    if (e % std::max(1, static_cast<int>(std::lround(s.gps.rate))) == 0) rmc_by_second.push_back(nmea_rmc(f));
  }

  // IMU: MTData2 at its rate, from the trajectory's derivatives.
  {
    Rng rng(o.seed, 0x1A1A);
    const Vec3 gyro_bias(rng.normal() * s.imu.gyro_bias, rng.normal() * s.imu.gyro_bias, rng.normal() * s.imu.gyro_bias);
    const Vec3 accel_bias(rng.normal() * s.imu.accel_bias, rng.normal() * s.imu.accel_bias, rng.normal() * s.imu.accel_bias);
    const double yaw_offset = rng.normal() * s.imu.yaw_error;
    const double h = 1.0 / Trajectory::kRate;
    const int samples = static_cast<int>(std::floor(report.sim_seconds * s.imu.rate)) + 1;
    const auto fine0 = static_cast<std::uint32_t>(unit(hash(o.seed, 0x7F)) * 1e9);
    for (int k = 0; k < samples; ++k) {
      const double t = k / s.imu.rate;
      // Derivatives by central differences, kept inside the trajectory.
      const double tc = std::clamp(t, h, std::max(h, traj.duration() - h));
      const PoseSample p = traj.at(t);
      const PoseSample pc = traj.at(tc);
      const PoseSample pa = traj.at(tc - h);
      const PoseSample pb = traj.at(tc + h);
      const Eigen::Matrix3d R = rotation(p.roll, p.pitch, p.yaw);
      const Eigen::Matrix3d Ra = rotation(pa.roll, pa.pitch, pa.yaw);
      const Eigen::Matrix3d Rb = rotation(pb.roll, pb.pitch, pb.yaw);
      const Eigen::AngleAxisd delta(Ra.transpose() * Rb);
      Vec3 omega = delta.axis() * delta.angle() / (2.0 * h);
      const Vec3 accel_w = (pb.p - 2.0 * pc.p + pa.p) / (h * h);
      Vec3 f = R.transpose() * (accel_w + Vec3(0, 0, kGravity));
      omega += gyro_bias + Vec3(rng.normal(), rng.normal(), rng.normal()) * s.imu.gyro_noise;
      f += accel_bias + Vec3(rng.normal(), rng.normal(), rng.normal()) * s.imu.accel_noise;
      // Orientation output: true roll/pitch, heading in true-north ENU with a small error.
      const Eigen::Quaterniond q(rotation(p.roll, p.pitch, p.yaw - geo.convergence() + yaw_offset));
      XsensSample x;
      x.counter = static_cast<std::uint16_t>(k);
      x.sample_time_fine = fine0 + static_cast<std::uint32_t>(std::llround(t * 10000.0));
      x.quaternion = {static_cast<float>(q.w()), static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z())};
      x.acceleration = {static_cast<float>(f.x()), static_cast<float>(f.y()), static_cast<float>(f.z())};
      x.rate_of_turn = {static_cast<float>(omega.x()), static_cast<float>(omega.y()), static_cast<float>(omega.z())};
      x.status = 0x3;  // self test passed, filter valid
      const auto bytes = xsens_mtdata2(x);
      const double arrival = t + 0.001 + static_cast<double>(bytes.size()) * 10.0 / s.imu.baud;
      check(w.write_serial(imu_stream, s.start_utc_ns + ns(arrival), bytes));
      ++report.imu_messages;
    }
  }

  // Wheel odometry on CAN: scale errors, and slip on loose ground.
  {
    Rng rng(o.seed, 0xCA11);
    const int frames = static_cast<int>(std::floor(report.sim_seconds * s.wheels.rate)) + 1;
    double dist_left = 0.0, dist_right = 0.0;
    double last_t = 0.0;
    for (int k = 0; k < frames; ++k) {
      const double t = k / s.wheels.rate;
      const PoseSample p = traj.at(t);
      const TerrainClass under = world->terrain(p.p.x(), p.p.y());
      const double slip = under == TerrainClass::street ? 0.2 * s.wheels.slip : s.wheels.slip;
      const double moving = std::abs(p.v) > 1e-3 ? 1.0 : 0.0;
      const double vl = p.v_left * s.wheels.scale_left * (1.0 + moving * slip * std::abs(rng.normal()));
      const double vr = p.v_right * s.wheels.scale_right * (1.0 + moving * slip * std::abs(rng.normal()));
      dist_left += vl * (t - last_t);
      dist_right += vr * (t - last_t);
      last_t = t;
      recording::CanFrame frame;
      frame.time_ns = s.start_utc_ns + ns(t + 0.0004);
      frame.id = speeds->id;
      frame.length = static_cast<std::uint8_t>(speeds->size);
      const std::span<std::uint8_t> data(frame.data.data(), frame.length);
      bool ok = can::encode_signal(*speed_left, vl, data) == can::SignalError::none &&
                can::encode_signal(*speed_right, vr, data) == can::SignalError::none &&
                can::encode_signal(*counter, k % 256, data) == can::SignalError::none &&
                can::encode_signal(*status, 0, data) == can::SignalError::none;
      check(w.write_can(can_stream, frame));
      recording::CanFrame tf;
      tf.time_ns = frame.time_ns + 150'000;
      tf.id = ticks->id;
      tf.length = static_cast<std::uint8_t>(ticks->size);
      const std::span<std::uint8_t> tdata(tf.data.data(), tf.length);
      ok = ok &&
           can::encode_signal(*ticks_left, std::round(dist_left * s.wheels.ticks_per_metre), tdata) ==
               can::SignalError::none &&
           can::encode_signal(*ticks_right, std::round(dist_right * s.wheels.ticks_per_metre), tdata) ==
               can::SignalError::none;
      if (!ok) return fail("wheel odometry does not fit the robot DBC's signals at t = " + std::to_string(t) + " s");
      check(w.write_can(can_stream, tf));
      report.can_frames += 2;
    }
  }

  // The e-stop line: its level at the start, then each press; mechanical
  // contacts bounce on release (two short re-closures within 4 ms).
  {
    auto level = [&](double t, bool v) {
      check(w.write_gpio(gpio_stream, s.start_utc_ns + ns(t), "ESTOP", v));
      ++report.gpio_levels;
    };
    level(0.0, false);
    for (const EstopPress& p : s.estop) {
      if (p.at >= report.sim_seconds) break;
      const double off = p.at + p.hold;
      level(p.at, true);
      level(off, false);
      level(off + 0.0012, true);
      level(off + 0.0019, false);
      level(off + 0.0031, true);
      level(off + 0.0040, false);
    }
  }

  // Camera frames (simulated: camera.hpp), each written when its exposure
  // ends plus a transfer's 20 ms; the winter season's frames are taken half
  // a period later, so no frame of one season is where one of the other was.
  if (o.camera) {
    const auto t_camera = Clock::now();
    const CameraSpec& cs = o.camera_spec;
    const int camera_stream =
        w.add_image_stream("camera", std::string("simulated camera, ") + season_name(o.season) + ", grey " +
                                         std::to_string(cs.width) + " x " + std::to_string(cs.height) + " at " +
                                         std::to_string(static_cast<int>(cs.rate)) + " Hz");
    CameraRenderer camera(*world, cs, o.season, o.seed);
    std::vector<std::uint8_t> frame(static_cast<std::size_t>(cs.width) * static_cast<std::size_t>(cs.height));
    const double phase = o.season == Season::winter ? 0.5 / cs.rate : 0.0;
    const auto frames = static_cast<std::uint64_t>(std::floor((report.sim_seconds - phase) * cs.rate)) + 1;
    for (std::uint64_t k = 0; k < frames && st; ++k) {
      const double t = phase + static_cast<double>(k) / cs.rate;
      camera.render(traj.at(t), k, frame);
      check(w.write_image(camera_stream, s.start_utc_ns + ns(t + 0.02), static_cast<std::uint32_t>(k), frame, cs.width,
                          cs.height));
      ++report.camera_frames;
      if (o.progress && k % 16 == 0) o.progress(t, report.sim_seconds);
    }
    report.camera_rays = camera.rays();
    report.camera_seconds = seconds_since(t_camera);
  }

  // Lidar data and position packets, in the order they leave the sensor.
  Sightings sightings;
  if (o.lidar_packets) {
    const auto t_lidar = Clock::now();
    LidarSim lidar(decoder, s, *world, traj, o.seed);
    std::array<std::uint8_t, vel::kDataPacketSize> pkt{};
    const auto packets = static_cast<std::uint64_t>(std::floor(report.sim_seconds * 1e6 / lidar.packet_period_us()));
    for (std::uint64_t i = 0; i < packets && st; ++i) {
      lidar.build(i, s.start_utc_ns, pkt);
      // Sent once its last firing is done, plus the sensor's latency.
      const double sent = (lidar.packet_start_us(i) + lidar.packet_period_us()) * 1e-6 + 60e-6 +
                          20e-6 * unit(hash(o.seed, 0x5E, i));
      check(w.write_udp(lidar_stream, s.start_utc_ns + ns(sent), pkt, 0xC0A801C9u, 2368));
      ++report.lidar_packets;
      if (i % 14 == 13) {
        // About one position packet per 14 data packets, echoing the last RMC of a whole second.
        const double now = sent + 30e-6;
        const auto second = static_cast<std::size_t>(std::floor(now));
        const std::string& rmc = rmc_by_second[std::min(second, rmc_by_second.size() - 1)];
        const std::int64_t utc = s.start_utc_ns + ns(now);
        const auto us = static_cast<std::uint32_t>((utc / 1000) % 3'600'000'000LL);
        check(w.write_udp(position_stream, utc, position_packet(us, 2, rmc), 0xC0A801C9u, 8308));
        ++report.position_packets;
      }
      if (o.progress && i % 256 == 0) o.progress(lidar.packet_start_us(i) * 1e-6, report.sim_seconds);
    }
    report.rays = lidar.rays();
    sightings = lidar.take_sightings();
    report.returns = lidar.returns();
    report.lidar_seconds = seconds_since(t_lidar);
    if (o.progress) o.progress(report.sim_seconds, report.sim_seconds);
  }
  check(w.close());
  if (!st) return fail(st.message());

  if (o.truth) {
    if (Status t = write_truth(o.out + "/truth", s, o.seed, *world, roads, traj, geo, sightings); !t) return fail(t.message());
    if (Status t = write_osm(o.out + "/world.osm", roads, s, geo); !t) return fail(t.message());
  }
  report.total_seconds = seconds_since(t_start);
  return report;
}

}  // namespace trailnav::sim
