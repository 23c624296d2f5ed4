// Traversability from demonstrations end to end (`trailnav trav-train`,
// `trav-eval`): robot profiles and their YAML errors, the per-cell truth, and
// a large and a small robot each driven over its own kind of ground in a
// simulated world, then scored on another layout: the large one learns that
// the meadow's grass is traversable, the small one that it is not — from
// the demonstrations alone (simulated truth).
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "simulator.hpp"
#include "trav_run.hpp"
#include "world.hpp"

namespace trailnav::eval {
namespace {

namespace fs = std::filesystem;
namespace trav = perception::trav;

std::string temp_path(const std::string& name) {
  return (fs::temp_directory_path() / ("trailnav-trav-" + std::to_string(::getpid()) + "-" + name)).string();
}

TEST(TravProfiles, BuiltInAndFromYamlWithErrorsThatNameTheLine) {
  const auto large = builtin_profile("large");
  const auto small = builtin_profile("small");
  ASSERT_TRUE(large && small);
  EXPECT_TRUE(large->ground[static_cast<std::size_t>(perception::TerrainClass::grass)]);
  EXPECT_FALSE(small->ground[static_cast<std::size_t>(perception::TerrainClass::grass)]);
  EXPECT_FALSE(small->ground[static_cast<std::size_t>(perception::TerrainClass::vegetation)]);
  EXPECT_TRUE(small->ground[static_cast<std::size_t>(perception::TerrainClass::dirt)]);
  EXPECT_GT(large->footprint.width, small->footprint.width);
  EXPECT_NE(load_profile("medium").error.find("unknown robot profile 'medium'"), std::string::npos);

  const std::string file = temp_path("profile.yaml");
  auto write = [&](const std::string& text) {
    std::ofstream(file) << text;
    return load_profile(file);
  };
  auto p = write("format: trailnav-robot-profile\nname: cart\nfootprint: {length: 0.9, width: 0.6}\nground: [street, grass]\n");
  ASSERT_TRUE(p.profile) << p.error;
  EXPECT_EQ(p.profile->name, "cart");
  EXPECT_DOUBLE_EQ(p.profile->footprint.length, 0.9);
  EXPECT_TRUE(p.profile->ground[0]);
  EXPECT_FALSE(p.profile->ground[1]);
  EXPECT_TRUE(p.profile->ground[2]);
  p = write("format: trailnav-robot-profile\nname: cart\nfootprint: {length: 0.9, width: 0.6}\nground: [street, sand]\n");
  EXPECT_NE(p.error.find("sand"), std::string::npos) << p.error;
  EXPECT_NE(p.error.find(file), std::string::npos) << p.error;
  p = write("format: trailnav-robot-profile\nname: cart\nfootprint: {length: 0.9}\nground: [street]\n");
  EXPECT_NE(p.error.find("width"), std::string::npos) << p.error;
  p = write("format: trailnav-robot-profile\nname: cart\nfootprint: {length: 0.9, width: 0.6}\nground: [street]\nspeed: 3\n");
  EXPECT_NE(p.error.find("speed"), std::string::npos) << p.error;
  fs::remove(file);
}

TEST(TravProfiles, TheTruthOfACellIsFreeGroundOfAKindTheRobotMayCross) {
  SimTruth t;
  for (TruthRaster* r : {&t.terrain, &t.obstacles}) {
    r->width = 20;
    r->height = 20;
    r->resolution = 0.05;
    r->x0 = 0.025;
    r->y0 = 0.025;
    r->data.assign(400, 0);
  }
  // Grass in the west half, street in the east; one obstacle pixel at (0.775, 0.775).
  for (int j = 0; j < 20; ++j) {
    for (int i = 0; i < 10; ++i) t.terrain.data[static_cast<std::size_t>(j * 20 + i)] = 2;
  }
  t.obstacles.data[15 * 20 + 15] = static_cast<std::uint8_t>(sim::ObstacleTruth::obstacle);
  const RobotProfile large = *builtin_profile("large"), small = *builtin_profile("small");
  EXPECT_EQ(truth_traversable(large, t, 0.1, 0.1, 0.2), std::optional<bool>(true));   // grass
  EXPECT_EQ(truth_traversable(small, t, 0.1, 0.1, 0.2), std::optional<bool>(false));
  EXPECT_EQ(truth_traversable(small, t, 0.7, 0.1, 0.2), std::optional<bool>(true));   // street
  EXPECT_EQ(truth_traversable(large, t, 0.7, 0.7, 0.2), std::optional<bool>(false));  // the obstacle pixel
  EXPECT_EQ(truth_traversable(small, t, 0.5, 0.1, 0.2), std::optional<bool>(false));  // half grass: in doubt, not
  EXPECT_EQ(truth_traversable(large, t, 5.0, 5.0, 0.2), std::nullopt);                // outside the world
  // Why not: the worst pixel (a solid obstacle over a ditch over undergrowth over forbidden ground).
  EXPECT_EQ(truth_cause(small, t, 0.1, 0.1, 0.2), std::optional<Untraversable>(Untraversable::ground));
  EXPECT_EQ(truth_cause(large, t, 0.7, 0.7, 0.2), std::optional<Untraversable>(Untraversable::solid));
  t.obstacles.data[1 * 20 + 1] = static_cast<std::uint8_t>(sim::ObstacleTruth::vegetation);
  t.obstacles.data[1 * 20 + 2] = static_cast<std::uint8_t>(sim::ObstacleTruth::negative);
  EXPECT_EQ(truth_cause(large, t, 0.1, 0.1, 0.2), std::optional<Untraversable>(Untraversable::ditch));
  EXPECT_EQ(truth_cause(small, t, 0.1, 0.1, 0.2), std::optional<Untraversable>(Untraversable::ditch));
  t.obstacles.data[1 * 20 + 2] = 0;
  EXPECT_EQ(truth_cause(large, t, 0.1, 0.1, 0.2), std::optional<Untraversable>(Untraversable::undergrowth));
  EXPECT_EQ(truth_cause(large, t, 0.7, 0.1, 0.2), std::optional<Untraversable>(Untraversable::none));
}

// An 80 m world: a street, a dirt road, then a path across the meadow or a dirt yard.
std::string world(const std::string& name, const std::string& route, const std::string& extra) {
  return "format: trailnav-scenario\nversion: 1\nname: " + name +
         "\norigin: {lat: 48.0301, lon: 7.8612, alt: 290}\nstart_utc: \"2026-06-22T09:10:00Z\"\n"
         "world:\n  extent: [-5, -15, 80, 15]\n  resolution: 0.1\n  background: grass\n"
         "  background_medium: {height: [0.1, 0.4], density: 12, clump_size: 0.8, cover: 0.9}\n"
         "trails:\n"
         "  - {name: street, class: street, width: 4, points: [[0, 0], [18, 0]]}\n"
         "  - {name: dirt, class: dirt, width: 3, points: [[18, 0], [36, 2]]}\n"
         "  - {name: meadow, class: grass, width: 2.5, points: [[36, 2], [56, 5], [76, 9]], medium: {height: [0.1, 0.4], density: 12}}\n"
         "  - {name: yard, class: dirt, width: 3, points: [[36, 2], [55, -4]]}\n" +
         extra + "route: " + route + "\nsensors:\n  lidar: {model: VLP-16}\n";
}

std::string simulate(const std::string& name, const std::string& yaml, std::uint64_t seed, double duration = 0.0) {
  const std::string file = temp_path(name + ".yaml");
  std::ofstream(file) << yaml;
  sim::SimOptions s;
  s.scenario = file;
  s.seed = seed;
  s.duration = duration;
  s.out = temp_path(name);
  fs::remove_all(s.out);
  const sim::SimReport r = sim::run_simulation(s);
  fs::remove(file);
  EXPECT_TRUE(r.error.empty()) << r.error;
  return s.out;
}

double grass_called(const TravEvalReport& r, trav::Method m) {
  for (const TravEvalRow& row : r.rows) {
    if (row.method != m || row.set != trav::FeatureSet::full) continue;
    const auto g = static_cast<std::size_t>(perception::TerrainClass::grass);
    return row.class_cells[g] ? static_cast<double>(row.called_traversable[g]) / static_cast<double>(row.class_cells[g]) : -1.0;
  }
  return -1.0;
}

TEST(TravEval, TheLargeRobotLearnsGrassIsTraversableTheSmallOneThatItIsNot) {
  const std::string obstacles =
      "obstacles:\n  - {type: box, center: [10, 4], size: [1, 1, 1], yaw: 0, remission: 40}\n"
      "  - {type: bush, center: [28, -5], radius: 1.3, height: 1.2}\n";
  const std::string large_drive =
      simulate("large", world("t-large", "[{trail: street}, {trail: dirt}, {trail: meadow}]", obstacles), 1);
  const std::string small_drive =
      simulate("small", world("t-small", "[{trail: street}, {trail: dirt}, {trail: yard}]", obstacles), 2);
  const std::string held_out = simulate(
      "eval",
      world("t-eval", "[{trail: street}, {trail: dirt}, {trail: yard}]",
            "obstacles:\n  - {type: wall, from: [5, 5], to: [25, 5], thickness: 0.3, height: 1.5}\n"
            "  - {type: box, center: [30, -6], size: [2, 2, 1.5], yaw: 30, remission: 60}\n"),
      3, 35.0);  // 40 m of it: street, dirt and the meadow beside (cheaper under the sanitizers)

  // Short local maps for a short drive.
  const trav::VocabularyConfig vocabulary;
  TravEvalReport scored[2];
  const char* names[2] = {"large", "small"};
  const std::string drives[2] = {large_drive, small_drive};
  for (int k = 0; k < 2; ++k) {
    TravRunOptions o;
    o.inputs = {drives[k]};
    o.profile = *builtin_profile(names[k]);
    o.recorder.local_map_distance = 10.0;
    const TravTrainReport t = run_trav_train(o, vocabulary, trav::LearnerConfig{});
    ASSERT_TRUE(t.error.empty()) << t.error;
    EXPECT_GE(t.sets.front().local_maps.size(), 3u);
    ASSERT_EQ(t.model.sets.size(), 4u);  // full, thesis, NoRe, NoRS
    EXPECT_GT(t.recorder.positive_words, 500u);
    for (const TravTrainSet& s : t.sets) EXPECT_GE(s.learnt, 3u) << names[k];
    // Through the model file, as trav-eval reads it.
    const std::string file = temp_path(std::string(names[k]) + ".tntrav");
    ASSERT_TRUE(trav::save_trav_model(file, t.model));
    const auto loaded = trav::load_trav_model(file);
    fs::remove(file);
    ASSERT_TRUE(loaded.model) << loaded.error;
    EXPECT_EQ(loaded.model->profile, names[k]);
    TravRunOptions e = o;
    e.inputs = {held_out};
    scored[k] = run_trav_eval(e, *loaded.model);
    ASSERT_TRUE(scored[k].error.empty()) << scored[k].error;
    ASSERT_EQ(scored[k].rows.size(), 8u);
    for (const TravEvalRow& row : scored[k].rows) {
      EXPECT_GT(row.scores.cells(), 1000u);
      std::printf("%s %s %s: precision %.3f recall %.3f specificity %.3f cells %llu grass called %.3f\n", names[k],
                  std::string(trav::method_name(row.method)).c_str(), std::string(trav::feature_set_name(row.set)).c_str(),
                  row.scores.precision(), row.scores.recall(), row.scores.specificity(),
                  static_cast<unsigned long long>(row.scores.cells()), grass_called(scored[k], row.method));
    }
  }
  for (trav::Method m : {trav::Method::pnb, trav::Method::pos}) {
    const double large = grass_called(scored[0], m), small = grass_called(scored[1], m);
    EXPECT_GT(large, 0.6) << trav::method_name(m);
    EXPECT_LT(small, 0.3) << trav::method_name(m);
    EXPECT_GT(large, small + 0.5) << trav::method_name(m);
  }
  for (const std::string& d : {large_drive, small_drive, held_out}) fs::remove_all(d);
}

}  // namespace
}  // namespace trailnav::eval
