// The chapter 4 station (perception/registration/station.hpp) on the
// thesis' simulated floor (board/sim/station_world.hpp). Simulated truth
// throughout.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <numbers>

#include "run_cli.hpp"
#include "station_eval.hpp"
#include "station_world.hpp"
#include "trailnav/perception/registration/station.hpp"
#include "trailnav/perception/registration/station_file.hpp"

namespace trailnav {
namespace {

namespace reg = perception::registration;
namespace st = sim::station;

// The ray caster against the floor's geometry: every return lies on a wall
// or an object (no noise), beams beyond the range give none.
TEST(StationWorld, EveryReturnLiesOnTheFloorsGeometry) {
  const st::World w = st::thesis_world();
  ASSERT_EQ(w.objects.size(), 3u);
  std::vector<st::Pose2> taught;
  for (const auto& o : w.objects) taught.push_back(o.pose);
  std::vector<st::Segment> seg = w.walls;
  const auto os = st::object_segments(w, taught);
  seg.insert(seg.end(), os.begin(), os.end());
  st::LaserConfig laser;
  laser.sigma = 0.0;
  for (const auto& o : w.objects) {
    const auto points = st::cast(seg, o.view, laser, 1);
    EXPECT_GT(points.size(), 300u) << o.name;  // of 361 beams, in a closed room
    const Eigen::Isometry3d pose = st::to_isometry(o.view);
    double far = 0.0;
    for (const auto& p : points) {
      const Eigen::Vector2d x = (pose * p.cast<double>()).head<2>();
      double best = 1e9;
      for (const auto& s : seg) {
        const Eigen::Vector2d e = s.b - s.a;
        const double u = std::clamp((x - s.a).dot(e) / e.squaredNorm(), 0.0, 1.0);
        best = std::min(best, (s.a + u * e - x).norm());
      }
      far = std::max(far, best);
    }
    EXPECT_LT(far, 1e-6) << o.name;  // the points are floats
  }
  // A set's motion turns the object about its own centre.
  const st::Pose2 m = st::move_of(w.objects[0], st::kThesisSets[3], 7);
  const st::Pose2 moved = st::compose(m, w.objects[0].pose);
  EXPECT_NEAR(std::hypot(moved.x - w.objects[0].pose.x, moved.y - w.objects[0].pose.y), 0.0, 1e-12);
  EXPECT_NEAR(std::abs(moved.theta - w.objects[0].pose.theta), 10.0 * std::numbers::pi / 180.0, 1e-12);
}

TEST(Station, PolygonsConfigsAndObjectsMarkedWhereNothingStands) {
  const std::vector<Eigen::Vector2d> square{{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  EXPECT_TRUE(reg::inside(square, {0.5, 0.5}));
  EXPECT_FALSE(reg::inside(square, {1.5, 0.5}));
  EXPECT_FALSE(reg::inside(square, {0.5, -0.01}));
  reg::StationConfig c;
  EXPECT_EQ(reg::check_station_config(c), "");
  c.fine_gate = 0.5f;  // wider than the coarse gate
  EXPECT_NE(reg::check_station_config(c).find("fine_gate"), std::string::npos);
  c = reg::StationConfig{};
  c.local_scans = 0;
  EXPECT_NE(reg::check_station_config(c).find("local_scans"), std::string::npos);
  // One scan of a wall; an object marked beside it holds nothing.
  std::vector<reg::StationScan> scans(1);
  for (int i = 0; i < 100; ++i) scans[0].points.emplace_back(2.0f, -1.0f + 0.02f * static_cast<float>(i), 0.0f);
  const reg::StationObject nothing{"ghost", {{5, 5}, {6, 5}, {6, 6}}};
  const reg::BuiltStation b = reg::build_station(scans, std::span<const reg::StationObject>(&nothing, 1), reg::StationConfig{});
  EXPECT_NE(b.error.find("ghost"), std::string::npos) << b.error;
  EXPECT_NE(b.error.find("0 points"), std::string::npos) << b.error;
}

// The thesis' experiment (§4.3.1), three visits per object and set: the
// multi-body registration finds each moved object; one rigid body does not.
// Errors are of the object's pose in the robot's frame, in the taught frame
// (laid onto the world's by the teach-in's poses). Measured (seed 1,
// 2026-12-05): the largest set mean 5.5 mm (box), 3.4 (shelf), 5.0 (table),
// 0.74 / 0.35 / 0.37 deg; the largest error 11.5 / 6.0 / 7.7 mm and 0.95 /
// 0.60 / 0.83 deg; one body 39–290 mm and 0.1–10 deg, the set's own motion.
// The bounds leave room for the sanitizers' floating-point differences,
// not for a regression.
TEST(Station, TheThesisSimulationFindsEveryMovedObjectWhereOneBodyCannot) {
  eval::StationEvalOptions o;
  o.runs = 3;
  const eval::StationEvalResult r = eval::evaluate_station_sim(o);
  ASSERT_EQ(r.error, "");
  ASSERT_EQ(r.objects.size(), 3u);
  for (const eval::StationObjectResult& ob : r.objects) {
    // The teach-in: odometry errors of centimetres taken out.
    EXPECT_GT(ob.teach_largest_correction, 0.03) << ob.name;
    EXPECT_LT(ob.teach_error_mm, 8.0) << ob.name;
    ASSERT_EQ(ob.sets.size(), 6u);
    for (const eval::StationSetResult& s : ob.sets) {
      SCOPED_TRACE(ob.name + " set " + std::to_string(s.set));
      EXPECT_EQ(s.unobserved, 0);
      EXPECT_LT(s.translation_mm.mean, 7.0);
      EXPECT_LT(s.translation_mm.max, 14.0);
      EXPECT_LT(s.rotation_deg.mean, 1.0);
      EXPECT_LT(s.rotation_deg.max, 1.3);
      // One body: the object's motion is missed.
      if (s.translation > 0.0) {
        EXPECT_GT(s.single_translation_mm.mean, 600.0 * s.translation);
      }
      if (s.rotation > 0.0) {
        EXPECT_GT(s.single_rotation_deg.mean, 0.8 * s.rotation * 180.0 / std::numbers::pi);
      }
    }
  }
}

// The teach-in as a pose graph over every pair of scans: on the simulated
// floor its poses end closer to the truth than the Gauss–Seidel rounds'
// (measured 2026-12-05: largest pose error 1.7 / 2.4 / 2.6 mm for the box,
// shelf and table against 5.6 / 4.4 / 3.2 mm), and the visits' set means
// stay within 4.1 mm.
TEST(Station, TheTeachInAsAPoseGraphEndsCloserToTheTruth) {
  eval::StationEvalOptions o;
  o.runs = 2;
  o.station.teach_graph = true;
  const eval::StationEvalResult graph = eval::evaluate_station_sim(o);
  ASSERT_EQ(graph.error, "");
  o.station.teach_graph = false;
  o.runs = 1;
  const eval::StationEvalResult rounds = eval::evaluate_station_sim(o);
  ASSERT_EQ(rounds.objects.size(), graph.objects.size());
  for (std::size_t k = 0; k < graph.objects.size(); ++k) {
    const eval::StationObjectResult& g = graph.objects[k];
    SCOPED_TRACE(g.name);
    EXPECT_LT(g.teach_error_mm, 3.5);
    EXPECT_LT(g.teach_error_mm, rounds.objects[k].teach_error_mm);
    for (const eval::StationSetResult& s : g.sets) EXPECT_LT(s.translation_mm.mean, 6.0) << "set " << s.set;
  }
}

// Cases constructed from the real Freiburg 079 log (real scans, applied
// motions; docs/registration.md): the places passed twice, one visit per
// set, three teach-in rounds (a third of the time, for the sanitizers'
// runs). Measured (2026-12-05): 11 places (4 left out as moved by
// themselves), 8 of them with every set within 15 mm and 1.5 deg (4, 6 and 9
// not: an object 1.5 m long sliding along itself, a small one turned the
// wrong way, a stray visit); with ten visits and ten rounds the working
// places' set means are 4–13 mm and 0.05–1.3 deg. One body misses every
// applied translation.
TEST(Station, CasesConstructedFromARealLog) {
  eval::StationCarmenOptions o;
  o.log = "../shared/data/carmen/freiburg-079-corrected.log.gz";
  o.runs = 1;
  o.places = 12;
  o.station.teach_rounds = 3;  // a third of the time (the sanitizers' runs); the figures as with 10
  const eval::StationEvalResult r = eval::evaluate_station_carmen(o);
  ASSERT_EQ(r.error, "");
  ASSERT_GE(r.objects.size(), 10u);
  EXPECT_LE(r.places_changed, 4);  // objects that moved by themselves between the passes, judged by the log's poses
  int good = 0;
  for (const eval::StationObjectResult& ob : r.objects) {
    bool all = true;
    for (const eval::StationSetResult& s : ob.sets) {
      all = all && s.translation_mm.mean < 15.0 && s.rotation_deg.mean < 1.5;
      if (s.translation > 0.0) {
        EXPECT_GT(s.single_translation_mm.mean, 80.0) << ob.name << " set " << s.set;
      }
    }
    std::printf("[ station ] %s %s: %s\n", ob.name.c_str(), ob.where.c_str(), all ? "every set within 15 mm, 1.5 deg" : "not");
    good += all ? 1 : 0;
  }
  std::printf("[ station ] %d of %zu places good\n", good, r.objects.size());
  EXPECT_GE(good, 7);
}

// The station file: what is written loads back bit for bit; damaged, cut
// or foreign bytes are refused with what is wrong.
TEST(StationFile, RoundTripAndDamageRefusedWithItsReason) {
  reg::StationFile f;
  f.name = "dock";
  f.bodies.push_back({"surroundings", {}, {{1.0f, 2.0f, 0.0f}, {1.5f, 2.0f, 0.0f}}});
  f.bodies.push_back({"table", {{0, 0}, {1, 0}, {1, 1}}, {{0.5f, 0.5f, 0.0f}}});
  const std::vector<std::uint8_t> bytes = reg::serialize_station(f);
  const reg::LoadedStation back = reg::parse_station(bytes, "a.tnst");
  ASSERT_TRUE(back.station) << back.error;
  EXPECT_EQ(back.station->name, "dock");
  ASSERT_EQ(back.station->bodies.size(), 2u);
  EXPECT_EQ(back.station->bodies[1].name, "table");
  EXPECT_EQ(back.station->bodies[1].polygon.size(), 3u);
  EXPECT_EQ(back.station->bodies[0].points[1], reg::Point(1.5f, 2.0f, 0.0f));
  EXPECT_EQ(reg::serialize_station(*back.station), bytes);

  std::vector<std::uint8_t> damaged = bytes;
  damaged[30] ^= 0x10;
  EXPECT_NE(reg::parse_station(damaged, "a.tnst").error.find("checksum"), std::string::npos);
  const std::vector<std::uint8_t> cut(bytes.begin(), bytes.end() - 9);
  EXPECT_NE(reg::parse_station(cut, "a.tnst").error.find("a.tnst"), std::string::npos);
  EXPECT_FALSE(reg::parse_station(cut, "a.tnst").station);
  std::vector<std::uint8_t> other = bytes;
  other[8] = 7;  // version 7
  EXPECT_NE(reg::parse_station(other, "a.tnst").error.find("version 7"), std::string::npos);
  const std::vector<std::uint8_t> foreign{'P', 'K', 3, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  EXPECT_NE(reg::parse_station(foreign, "a.tnst").error.find("not a trailnav station file"), std::string::npos);
  // A loaded station becomes bodies to register against again.
  reg::StationFile big;
  big.name = "x";
  big.bodies.push_back({"surroundings", {}, {}});
  for (int i = 0; i < 50; ++i) big.bodies[0].points.emplace_back(0.02f * static_cast<float>(i), 0.0f, 0.0f);
  const reg::BuiltStation built = reg::station_from_file(big, reg::StationConfig{});
  ASSERT_EQ(built.error, "");
  EXPECT_EQ(built.station.bodies[0].tree.size(), 50u);
  EXPECT_NE(reg::station_from_file(f, reg::StationConfig{}).error.find("'surroundings' holds 2 points"), std::string::npos);
}

int run(const std::vector<std::string>& args, std::string& out) { return test::run_cli(args, out); }

// `trailnav station teach` on sixteen scans of the real Freiburg log with a
// cabinet marked as a box: a station file with the surroundings and the
// cabinet, and its picture; `trailnav station locate` of a later pass finds
// the cabinet where it was taught; a polygon of two corners is refused with its
// object's line, and nothing is written.
TEST(StationTeach, ARealLogsScansAndAMarkedObjectMakeAStationFile) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("station-teach-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string objects = (dir / "objects.yaml").string();
  std::ofstream(objects) << "objects:\n  - name: cabinet\n    box: {centre: [-14.32, -0.96], size: [1.1, 1.5], heading_deg: 0}\n";
  const std::string out = (dir / "dock.tnst").string(), png = (dir / "dock.png").string();
  std::string text;
  ASSERT_EQ(run({"station", "teach", "../shared/data/carmen/freiburg-079-corrected.log.gz", "--from", "1480", "--to", "1495",
                 "--objects", objects, "--out", out, "--png", png, "--name", "dock"},
                text),
            0)
      << text;
  EXPECT_NE(text.find("taught from 16 scans"), std::string::npos) << text;
  const reg::LoadedStation loaded = reg::load_station(out);
  ASSERT_TRUE(loaded.station) << loaded.error;
  EXPECT_EQ(loaded.station->name, "dock");
  ASSERT_EQ(loaded.station->bodies.size(), 2u);
  EXPECT_EQ(loaded.station->bodies[1].name, "cabinet");
  EXPECT_GT(loaded.station->bodies[1].points.size(), 200u);
  EXPECT_GT(loaded.station->bodies[0].points.size(), 1000u);
  EXPECT_GT(std::filesystem::file_size(png), 1000u);
  // A later pass by the same cabinet (scans 553–562, 121 s, against 1480–1495
  // at 328 s), located against the file: nothing moved it, and the answer says
  // so (measured 2026-12-05: its centre 4 mm and 3 mm off, 0.02 deg).
  ASSERT_EQ(run({"station", "locate", out, "../shared/data/carmen/freiburg-079-corrected.log.gz", "--from", "553", "--to", "562",
                 "--report", "json", "--png", (dir / "visit.png").string()},
                text),
            0)
      << text;
  double dx = 1.0, dy = 1.0, turned = 10.0;
  const std::size_t at = text.find("\"name\": \"cabinet\"");
  ASSERT_NE(at, std::string::npos) << text;
  ASSERT_EQ(std::sscanf(text.c_str() + text.find("\"moved_x\"", at), "\"moved_x\": %lf, \"moved_y\": %lf, \"turned_deg\": %lf", &dx, &dy,
                        &turned),
            3)
      << text;
  EXPECT_LT(std::hypot(dx, dy), 0.015) << text;
  EXPECT_LT(std::abs(turned), 0.5) << text;
  EXPECT_NE(text.find("\"observed\": true", at), std::string::npos) << text;
  EXPECT_GT(std::filesystem::file_size(dir / "visit.png"), 1000u);
  // A damaged file is refused with its reason.
  {
    std::fstream damaged(out, std::ios::in | std::ios::out | std::ios::binary);
    damaged.seekp(40);
    damaged.put('\x7f');
  }
  EXPECT_NE(run({"station", "locate", out, "../shared/data/carmen/freiburg-079-corrected.log.gz", "--from", "553", "--to", "562"},
                text),
            0);
  EXPECT_NE(text.find("checksum"), std::string::npos) << text;
  const std::string bad = (dir / "bad.yaml").string();
  std::ofstream(bad) << "objects:\n  - name: a\n    polygon: [[0, 0], [1, 0]]\n";
  EXPECT_NE(run({"station", "teach", "../shared/data/carmen/freiburg-079-corrected.log.gz", "--from", "1480", "--to", "1495",
                 "--objects", bad, "--out", (dir / "x.tnst").string()},
                text),
            0);
  EXPECT_NE(text.find("bad.yaml:2"), std::string::npos) << text;  // the object's line
  EXPECT_NE(text.find("3 to 1024 corners"), std::string::npos) << text;
  EXPECT_FALSE(std::filesystem::exists(dir / "x.tnst"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace trailnav
