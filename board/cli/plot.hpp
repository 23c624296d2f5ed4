// Line plots a person can read, as PNG: axes with ticks and their values,
// axis titles, a grid, a title with notes above and a legend beside
// (precision-recall curves of `trailnav place-eval`). Not for real-time threads.
#pragma once

#include <string>
#include <vector>

#include "figure.hpp"

namespace trailnav::cli {

struct PlotSeries {
  std::string label;  // in the legend
  Rgb color;
  std::vector<double> x, y;
  bool mark_last_best = false;  // a ring at (best_x, best_y)
  double best_x = 0.0, best_y = 0.0;
};

struct Plot {
  std::string title;
  std::vector<std::string> notes;
  std::string x_label, y_label;
  double x_min = 0.0, x_max = 1.0, y_min = 0.0, y_max = 1.0;
  double tick = 0.1;  // grid and labels every `tick` on both axes
  std::vector<PlotSeries> series;
};

Canvas draw_plot(const Plot& plot);
Status write_plot(const std::string& path, const Plot& plot);

}  // namespace trailnav::cli
