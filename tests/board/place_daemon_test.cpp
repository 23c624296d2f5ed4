// trailnavd's place task end to end (issue 41): a place database made by
// place-map from a recording of the real Nordland summer frames (poses 10 m
// apart), the daemon built from a config with `camera: {input: tunnel}` and
// `place:`, the winter frames sent through the image tunnel one at a time,
// and trailnav_msgs/PlaceMatch and the place pose received over a
// loopback-only DDS domain: the matched images follow the winter drive, the
// poses carry the database's and a covariance, and the health says so.
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <string>
#include <thread>

#include "daemon.hpp"
#include "dds.hpp"
#include "geometry_msgs.h"
#include "place_map.hpp"
#include "sim_truth.hpp"
#include "simulator.hpp"
#include "robot_config.hpp"
#include "subscriber.hpp"
#include "test_data.hpp"
#include "trailnav/drivers/camera/image_file.hpp"
#include "trailnav/drivers/camera/image_tunnel.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/runtime/host_clock.hpp"
#include "trailnav_msgs.h"

using namespace trailnav;
using namespace trailnav::daemon;
namespace fs = std::filesystem;
namespace camera = trailnav::drivers::camera;

namespace {

constexpr std::uint32_t kDomain = 95;
constexpr int kFrames = 200;

std::vector<std::uint8_t> nordland(const char* season, int k) {
  char name[96];
  std::snprintf(name, sizeof name, "nordland/%s/images-%05d.png", season, 10 * (k + 1));
  return camera::read_grey_image(test::shared_data(name)).image.pixels;
}

// One frame through the image tunnel to 127.0.0.1:port.
void send_frame(int s, std::uint16_t port, const std::vector<std::uint8_t>& px, int w, int h, std::uint32_t sequence) {
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(port);
  to.sin_addr.s_addr = htonl(0x7F000001u);
  for (std::size_t i = 0; i < camera::fragment_count(w, h); ++i) {
    const camera::TunnelFragment f = camera::encode_fragment(px, w, h, sequence, 0, i);
    ::sendto(s, f.bytes.data(), f.size, 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
  }
}

// trailnavd with the camera's tunnel input (frames of width x height,
// reduced to 64 x 32) and the place task on DIR/summer.tnplace, started;
// null (and a failure) when it does not start.
std::unique_ptr<Daemon> start_place_daemon(const fs::path& dir, int width, int height, std::uint32_t domain) {
  const std::string config = (dir / "robot.yaml").string();
  std::ofstream(config) << "runtime: {realtime: off, lock_memory: false, log_level: warn, log_sink: stderr}\n"
                        << "camera: {input: tunnel, tunnel_port: 0, width: " << width << ", height: " << height
                        << ", out_width: 64, out_height: 32}\n"
                        << "place: {database: summer.tnplace, frame: map}\n"
                        << "dds: {domain: " << domain << ", cyclone_config: loopback, health_period_s: 0.2}\n"
                        << "tasks: {preset: auto}\n";
  RobotConfigResult loaded = load_robot_config(config);
  if (!loaded.config) {
    ADD_FAILURE() << loaded.error;
    return nullptr;
  }
  auto made = Daemon::create(*loaded.config);
  if (!made.daemon || !made.daemon->start()) {
    ADD_FAILURE() << "trailnavd did not start: " << made.error;
    return nullptr;
  }
  return std::move(made.daemon);
}

// A recording of the first `images` Nordland summer frames (cycled past
// the 2,400) at 4 Hz, their poses 10 m apart along x at (y, yaw), and the
// place database place-map makes of it in DIR/summer.tnplace.
void make_summer_database(const fs::path& dir, int images, double y, double yaw, std::size_t& entries) {
  auto made = recording::RecordingWriter::create((dir / "summer").string(), "Nordland summer");
  ASSERT_TRUE(made.writer) << made.error;
  const int cam = made.writer->add_image_stream("camera");
  {
    std::ofstream poses(dir / "poses.csv");
    poses << std::fixed << std::setprecision(6);
    for (int k = 0; k < images; ++k) {
      const std::int64_t t = 1'700'000'000'000'000'000 + k * 250'000'000LL;
      ASSERT_TRUE(made.writer->write_image(cam, t, static_cast<std::uint32_t>(k), nordland("summer", k % 2400), 64, 32).is_ok());
      poses << static_cast<double>(t) * 1e-9 << "," << 10 * k << "," << y << "," << yaw << "\n";
    }
  }
  ASSERT_TRUE(made.writer->close().is_ok());
  eval::PlaceMapOptions mo;
  mo.recording = (dir / "summer").string();
  mo.poses = (dir / "poses.csv").string();
  const eval::PlaceMapReport map = eval::make_place_map(mo);
  ASSERT_TRUE(map.error.empty()) << map.error;
  entries = map.database.entries.size();
  ASSERT_EQ(perception::place::save_place_database(map.database, (dir / "summer.tnplace").string()), "");
}

}  // namespace

TEST(PlaceDaemon, WinterFramesThroughTheTunnelAreLocalisedInASummerDatabase) {
  host_clock_start();
  const fs::path dir = fs::temp_directory_path() / ("trailnav-place-daemon-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  // The database: a recording of the summer frames, place-map with their poses.
  std::size_t entries = 0;
  make_summer_database(dir, kFrames, 5.0, 0.25, entries);
  ASSERT_EQ(entries, static_cast<std::size_t>(kFrames));
  const std::unique_ptr<Daemon> running = start_place_daemon(dir, 64, 32, kDomain);
  ASSERT_TRUE(running);
  Daemon& daemon = *running;
  const std::uint16_t port = daemon.camera_tunnel_port();
  ASSERT_NE(port, 0);

  auto domain = dds::Domain::create(kDomain, dds::loopback_config());
  ASSERT_TRUE(domain.domain) << domain.error;
  auto matches = dds::Subscriber::create(*domain.domain, "trailnav/place_match", &trailnav_msgs_msg_dds__PlaceMatch__desc, 0);
  auto poses = dds::Subscriber::create(*domain.domain, "trailnav/place_pose",
                                       &geometry_msgs_msg_dds__PoseWithCovarianceStamped__desc, 0);
  ASSERT_TRUE(matches.subscriber && poses.subscriber);

  const int s = ::socket(AF_INET, SOCK_DGRAM, 0);
  // One frame, then the answer it brings (or a second), then the next: the
  // filter sees every frame whatever the machine's load. With the default
  // lag of 10 frames, frame k brings the answer for frame k - 10.
  constexpr int kLag = 10;
  int answered = 0, right = 0, late_right = 0, in_sequence = 0, in_sequence_right = 0, confident = 0, confident_right = 0;
  double last_probability = -1.0;
  for (int k = 0; k < kFrames; ++k) {
    send_frame(s, port, nordland("winter", k), 64, 32, static_cast<std::uint32_t>(k + 1));
    const int answer = k - kLag;
    if (answer < 0) {
      // No answer yet: wait until the task has taken the frame.
      for (int wait = 0; wait < 1000 && daemon.place_counters().frames < static_cast<std::uint64_t>(k + 1); ++wait)
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      continue;
    }
    bool got = false;
    for (int wait = 0; wait < 10 && !got; ++wait) {
      matches.subscriber->take(0.1, [&](const dds::ReceivedSample& r) {
        const auto& m = *static_cast<const trailnav_msgs_msg_dds__PlaceMatch_*>(r.sample);
        if (m.frame_sequence != static_cast<std::uint32_t>(answer + 1)) return;
        got = true;
        ++answered;
        const int off = static_cast<int>(m.database_index) - answer;
        right += std::abs(off) <= 5 ? 1 : 0;
        if (answer >= kFrames / 2) late_right += std::abs(off) <= 5 ? 1 : 0;
        if (m.in_sequence) {
          ++in_sequence;
          in_sequence_right += std::abs(off) <= 5 ? 1 : 0;
          if (m.probability >= 0.3) {  // what the pose thread takes by default (place.min_probability)
            ++confident;
            confident_right += std::abs(off) <= 5 ? 1 : 0;
          }
        }
        last_probability = m.probability;
        EXPECT_EQ(std::string(m.header.frame_id), "map");
        EXPECT_EQ(m.lag_frames, static_cast<std::uint32_t>(kLag));
        EXPECT_EQ(m.in_sequence, m.chain_length >= 10u);
        EXPECT_GE(m.probability, m.peak);
        EXPECT_LE(m.probability, 1.0 + 1e-9);
      });
    }
  }
  ::close(s);
  int pose_samples = 0;
  poses.subscriber->take(0.5, [&](const dds::ReceivedSample& r) {
    const auto& p = *static_cast<const geometry_msgs_msg_dds__PoseWithCovarianceStamped_*>(r.sample);
    ++pose_samples;
    EXPECT_EQ(std::string(p.header.frame_id), "map");
    EXPECT_NEAR(p.pose.pose.position.y, 5.0, 1e-6);  // every database pose has y = 5
    EXPECT_GE(p.pose.covariance[0], 4.0);             // the 2 m floor, squared
    EXPECT_GE(p.pose.covariance[35], 0.17 * 0.17 - 1e-9);
  });
  daemon.stop();
  std::printf("%d of %d frames answered, %d within 5 images of the truth (%d of the last %d); %d in sequences, %d of "
              "them right; %d of those with probability >= 0.3, %d right\n",
              answered, kFrames, right, late_right, kFrames / 2, in_sequence, in_sequence_right, confident, confident_right);
  EXPECT_EQ(answered, kFrames - kLag);
  EXPECT_GT(pose_samples, 0);
  // The online filter with ZCA learnt from the database and its answers 10
  // frames back (docs/place.md): 121 of the 190 within 5 images, every run
  // the same (the frames go in one at a time; the forward belief alone: 111
  // of 200, without ZCA 43; by chance 11). Of those in sequences with a
  // probability of at least 0.3, what the pose thread takes, 82 of 84 right.
  EXPECT_GE(right, 110);
  EXPECT_GE(confident, 70);
  EXPECT_GE(confident_right, confident * 95 / 100);
  EXPECT_GE(last_probability, 0.0);
  fs::remove_all(dir);
}

// The whole path on the simulator (issue 41; simulated truth, simulated
// camera): a summer drive of the urban scenario with the camera rendered,
// place-map on it with the true poses, and the winter drive's frames (snow,
// overcast, bare trees; taken half a frame period later) through the image
// tunnel into trailnavd at 128 x 64, reduced to 64 x 32 there: the database
// images trailnavd answers with lie where the winter robot was.
TEST(PlaceDaemon, ASimulatedWinterDriveIsLocalisedInASimulatedSummerDatabase) {
  host_clock_start();
  const fs::path dir = fs::temp_directory_path() / ("trailnav-place-sim-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  for (const sim::Season season : {sim::Season::summer, sim::Season::winter}) {
    sim::SimOptions so;
    so.scenario = "urban";
    so.duration = 60.0;
    so.lidar_packets = false;
    so.camera = true;
    so.camera_spec.rate = 5.0;
    so.season = season;
    so.out = (dir / sim::season_name(season)).string();
    const sim::SimReport r = sim::run_simulation(so);
    ASSERT_TRUE(r.error.empty()) << r.error;
    ASSERT_GE(r.camera_frames, 299u);
  }
  eval::PlaceMapOptions mo;
  mo.recording = (dir / "summer").string();
  const eval::PlaceMapReport map = eval::make_place_map(mo);
  ASSERT_TRUE(map.error.empty()) << map.error;
  EXPECT_NE(map.pose_source.find("simulated truth"), std::string::npos);
  const perception::place::PlaceDatabase& db = map.database;
  ASSERT_GE(db.entries.size(), 290u);
  ASSERT_EQ(perception::place::save_place_database(db, (dir / "summer.tnplace").string()), "");

  // The winter frames and where the robot was when each was taken.
  struct Frame {
    std::vector<std::uint8_t> pixels;
    double x = 0.0, y = 0.0;
  };
  std::vector<Frame> winter;
  {
    auto truth = eval::load_sim_truth((dir / "winter" / "truth").string());
    ASSERT_TRUE(truth.truth) << truth.error;
    auto opened = recording::RecordingReader::open((dir / "winter").string());
    ASSERT_TRUE(opened.reader) << opened.error;
    while (auto e = opened.reader->next()) {
      if (e->kind != recording::StreamKind::image) continue;
      eval::TruthAt at;
      ASSERT_TRUE(eval::truth_at(truth.truth->trajectory, e->time_ns - 20'000'000, at));
      winter.push_back({std::vector<std::uint8_t>(e->payload.begin(), e->payload.end()), at.x, at.y});
      ASSERT_EQ(e->image_width, 128);
    }
  }
  ASSERT_GE(winter.size(), 299u);

  const std::unique_ptr<Daemon> running = start_place_daemon(dir, 128, 64, kDomain + 1);
  ASSERT_TRUE(running);
  Daemon& daemon = *running;
  auto domain = dds::Domain::create(kDomain + 1, dds::loopback_config());
  ASSERT_TRUE(domain.domain) << domain.error;
  auto matches = dds::Subscriber::create(*domain.domain, "trailnav/place_match", &trailnav_msgs_msg_dds__PlaceMatch__desc, 0);
  ASSERT_TRUE(matches.subscriber);
  const int s = ::socket(AF_INET, SOCK_DGRAM, 0);
  constexpr int kLag = 10;
  int answered = 0, near = 0, in_sequence = 0, in_sequence_near = 0, confident = 0, confident_near = 0;
  double worst_in_sequence = 0.0, worst_confident = 0.0;
  for (std::size_t k = 0; k < winter.size(); ++k) {
    send_frame(s, daemon.camera_tunnel_port(), winter[k].pixels, 128, 64, static_cast<std::uint32_t>(k + 1));
    if (k < kLag) {
      for (int wait = 0; wait < 1000 && daemon.place_counters().frames < k + 1; ++wait)
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      continue;
    }
    const std::size_t answer = k - kLag;
    bool got = false;
    for (int wait = 0; wait < 10 && !got; ++wait) {
      matches.subscriber->take(0.1, [&](const dds::ReceivedSample& r) {
        const auto& m = *static_cast<const trailnav_msgs_msg_dds__PlaceMatch_*>(r.sample);
        if (m.frame_sequence != answer + 1) return;
        got = true;
        ++answered;
        ASSERT_LT(m.database_index, db.entries.size());
        const perception::place::PlaceEntry& e = db.entries[m.database_index];
        const double off = std::hypot(e.x - winter[answer].x, e.y - winter[answer].y);
        near += off <= 5.0 ? 1 : 0;
        if (m.in_sequence) {
          ++in_sequence;
          in_sequence_near += off <= 5.0 ? 1 : 0;
          worst_in_sequence = std::max(worst_in_sequence, off);
          if (m.probability >= 0.3) {  // what the pose thread takes by default
            ++confident;
            confident_near += off <= 5.0 ? 1 : 0;
            worst_confident = std::max(worst_confident, off);
          }
        }
      });
    }
  }
  ::close(s);
  daemon.stop();
  std::printf("simulated: %d of %zu winter frames answered, %d within 5 m of the summer image's true place; %d in "
              "sequences, %d within 5 m (worst %.1f m); %d of those with probability >= 0.3, %d within 5 m (worst %.1f m)\n",
              answered, winter.size() - kLag, near, in_sequence, in_sequence_near, worst_in_sequence, confident,
              confident_near, worst_confident);
  // Measured (every run the same: the frames go in one at a time): 246 of
  // 290 within 5 m; 253 in sequences, 224 within 5 m; 150 with a
  // probability of at least 0.3 (what the pose thread takes), all within
  // 2.5 m. The open stretches with nothing but the street alias.
  EXPECT_EQ(answered, static_cast<int>(winter.size()) - kLag);
  EXPECT_GE(near, answered * 8 / 10);
  EXPECT_GE(in_sequence, answered * 8 / 10);
  EXPECT_GE(in_sequence_near, in_sequence * 8 / 10);
  EXPECT_GE(confident, 120);
  EXPECT_GE(confident_near, confident * 97 / 100);
  fs::remove_all(dir);
}

// The camera's and the place task's time in trailnavd (their budgets in the
// task presets, docs/place.md "Budgets"): a database of 10,000 images (the
// whole Nordland summer, 2,400 frames, four times and a sixth; the whitening
// learnt from it, by randomised subspace iteration) as the presets assume, 600 winter frames
// sent at the camera's 10 Hz in real time (not waiting for answers), then
// both tasks' execution times, overruns, and no real-time allocation. A
// minute: run with TRAILNAV_LONG_TESTS=1 (outside CI, as the lidar's).
TEST(PlaceDaemon, TheWholeSummerAsTheDatabaseAtTheCamerasRate) {
  if (std::getenv("TRAILNAV_LONG_TESTS") == nullptr) GTEST_SKIP() << "set TRAILNAV_LONG_TESTS=1 (benchmarks)";
  host_clock_start();
  const fs::path dir = fs::temp_directory_path() / ("trailnav-place-budget-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  constexpr int kImages = 10000;
  std::size_t entries = 0;
  make_summer_database(dir, kImages, 0.0, 0.0, entries);
  ASSERT_EQ(entries, static_cast<std::size_t>(kImages));
  const std::unique_ptr<Daemon> running = start_place_daemon(dir, 64, 32, kDomain + 2);
  ASSERT_TRUE(running);
  Daemon& daemon = *running;
  const int s = ::socket(AF_INET, SOCK_DGRAM, 0);
  auto next = std::chrono::steady_clock::now();
  for (int k = 0; k < 600; ++k) {
    send_frame(s, daemon.camera_tunnel_port(), nordland("winter", k), 64, 32, static_cast<std::uint32_t>(k + 1));
    next += std::chrono::milliseconds(100);
    std::this_thread::sleep_until(next);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ::close(s);
  const perception::place::PlaceCounters counters = daemon.place_counters();
  const auto camera_task = daemon.task_figures("camera"), place_task = daemon.task_figures("place");
  daemon.stop();
  ASSERT_TRUE(camera_task && place_task);
  std::printf("%s", daemon.task_report().c_str());
  std::printf("place: %llu frames taken, %llu answers\n", static_cast<unsigned long long>(counters.frames),
              static_cast<unsigned long long>(counters.steps));
  for (const auto* t : {&*camera_task, &*place_task})
    std::printf("budget %.3f ms: exec p50 %.3f p99 %.3f max %.3f ms, overruns %llu\n", t->budget_ms,
                nanos_to_seconds(t->stats.execution.p50) * 1e3, nanos_to_seconds(t->stats.execution.p99) * 1e3,
                nanos_to_seconds(t->stats.execution.max) * 1e3, static_cast<unsigned long long>(t->stats.overruns));
  EXPECT_GE(counters.frames, 590u);
  EXPECT_EQ(place_task->stats.overruns, 0u);
  EXPECT_EQ(camera_task->stats.overruns, 0u);
  EXPECT_EQ(daemon.summary().rt_allocations, 0u);
  fs::remove_all(dir);
}
