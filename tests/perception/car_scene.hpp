// The labelled SemanticKITTI scan (../shared/data/semantickitti, run from
// the repository root) split into its largest car — class 10, the instance
// with the most points — and everything else: a movable object and its
// static surroundings for the multi-body registration's test and benchmark.
#pragma once

#include <cstdint>
#include <fstream>
#include <map>
#include <vector>

#include "trailnav/perception/registration/cloud.hpp"

namespace trailnav::perception::registration {

struct CarScene {
  std::vector<Point> world, car;
};
inline CarScene car_scene() {
  std::ifstream fb("../shared/data/semantickitti/000000.bin", std::ios::binary);
  std::ifstream fl("../shared/data/semantickitti/000000.label", std::ios::binary);
  std::vector<Point> points;
  std::vector<std::uint32_t> labels;
  float x[4];
  while (fb.read(reinterpret_cast<char*>(x), sizeof x)) points.emplace_back(x[0], x[1], x[2]);
  std::uint32_t l = 0;
  while (fl.read(reinterpret_cast<char*>(&l), sizeof l)) labels.push_back(l);
  CarScene s;
  if (points.size() != labels.size()) return s;
  std::map<std::uint32_t, std::size_t> cars;
  for (std::uint32_t v : labels) {
    if ((v & 0xFFFFu) == 10u) ++cars[v >> 16];
  }
  std::uint32_t biggest = 0;
  std::size_t most = 0;
  for (const auto& [id, count] : cars) {
    if (count > most) {
      most = count;
      biggest = id;
    }
  }
  for (std::size_t i = 0; i < points.size(); ++i) {
    const bool is_car = (labels[i] & 0xFFFFu) == 10u && (labels[i] >> 16) == biggest;
    (is_car ? s.car : s.world).push_back(points[i]);
  }
  return s;
}

}  // namespace trailnav::perception::registration
