#include "plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace trailnav::cli {
namespace {

constexpr int kAxisWidth = 560, kAxisHeight = 420;
constexpr int kLeft = 70, kLegendWidth = 300, kBottom = 60;

void line(Canvas& c, int x0, int y0, int x1, int y1, Rgb color, int thick) {
  // Bresenham, each step a thick x thick square.
  const int dx = std::abs(x1 - x0), dy = -std::abs(y1 - y0);
  const int sx = x0 < x1 ? 1 : -1, sy = y0 < y1 ? 1 : -1;
  int err = dx + dy;
  for (;;) {
    c.fill(x0 - thick / 2, y0 - thick / 2, thick, thick, color);
    if (x0 == x1 && y0 == y1) break;
    const int e2 = 2 * err;
    if (e2 >= dy) {
      err += dy;
      x0 += sx;
    }
    if (e2 <= dx) {
      err += dx;
      y0 += sy;
    }
  }
}

void ring(Canvas& c, int cx, int cy, int r, Rgb color) {
  for (int a = 0; a < 72; ++a) {
    const double t0 = a * 2.0 * 3.14159265358979 / 72.0, t1 = (a + 1) * 2.0 * 3.14159265358979 / 72.0;
    line(c, cx + static_cast<int>(std::lround(r * std::cos(t0))), cy + static_cast<int>(std::lround(r * std::sin(t0))),
         cx + static_cast<int>(std::lround(r * std::cos(t1))), cy + static_cast<int>(std::lround(r * std::sin(t1))), color, 2);
  }
}

}  // namespace

Canvas draw_plot(const Plot& p) {
  const int text_lines = 1 + static_cast<int>(p.notes.size());
  const int top = 16 + Canvas::line_height(2) + static_cast<int>(p.notes.size()) * Canvas::line_height(1) + 16;
  const int width = kLeft + kAxisWidth + 30 + kLegendWidth;
  const int height = top + kAxisHeight + kBottom;
  (void)text_lines;
  const Rgb white{255, 255, 255}, black{0, 0, 0}, grid{220, 220, 220}, grey{90, 90, 90};
  Canvas c(width, height, white);
  int y = 12;
  c.text(kLeft, y, p.title, black, 2);
  y += Canvas::line_height(2);
  for (const std::string& n : p.notes) {
    c.text(kLeft, y, n, grey, 1);
    y += Canvas::line_height(1);
  }
  const auto px = [&](double x) {
    return kLeft + static_cast<int>(std::lround((x - p.x_min) / (p.x_max - p.x_min) * kAxisWidth));
  };
  const auto py = [&](double v) {
    return top + kAxisHeight - static_cast<int>(std::lround((v - p.y_min) / (p.y_max - p.y_min) * kAxisHeight));
  };
  // Grid and ticks.
  char label[32];
  const int ticks_x = static_cast<int>(std::lround((p.x_max - p.x_min) / p.tick));
  for (int k = 0; k <= ticks_x; ++k) {
    const double v = p.x_min + k * p.tick;
    const int x = px(v);
    line(c, x, top, x, top + kAxisHeight, grid, 1);
    line(c, x, top + kAxisHeight, x, top + kAxisHeight + 5, black, 1);
    std::snprintf(label, sizeof label, "%.1f", v);
    c.text(x - Canvas::text_width(label, 1) / 2, top + kAxisHeight + 9, label, black, 1);
  }
  const int ticks_y = static_cast<int>(std::lround((p.y_max - p.y_min) / p.tick));
  for (int k = 0; k <= ticks_y; ++k) {
    const double v = p.y_min + k * p.tick;
    const int yy = py(v);
    line(c, kLeft, yy, kLeft + kAxisWidth, yy, grid, 1);
    line(c, kLeft - 5, yy, kLeft, yy, black, 1);
    std::snprintf(label, sizeof label, "%.1f", v);
    c.text(kLeft - 8 - Canvas::text_width(label, 1), yy - 4, label, black, 1);
  }
  c.outline(kLeft, top, kAxisWidth + 1, kAxisHeight + 1, black);
  c.text(kLeft + kAxisWidth / 2 - Canvas::text_width(p.x_label, 2) / 2, top + kAxisHeight + 26, p.x_label, black, 2);
  // The y title written downwards, letter under letter.
  {
    const int h = static_cast<int>(p.y_label.size()) * Canvas::line_height(1);
    int ty = top + kAxisHeight / 2 - h / 2;
    for (char ch : p.y_label) {
      c.text(12, ty, std::string(1, ch), black, 1);
      ty += Canvas::line_height(1);
    }
  }
  // Curves, clipped to the axes.
  const auto clip_x = [&](int x) { return std::clamp(x, kLeft, kLeft + kAxisWidth); };
  const auto clip_y = [&](int v) { return std::clamp(v, top, top + kAxisHeight); };
  for (const PlotSeries& s : p.series) {
    for (std::size_t i = 1; i < s.x.size() && i < s.y.size(); ++i)
      line(c, clip_x(px(s.x[i - 1])), clip_y(py(s.y[i - 1])), clip_x(px(s.x[i])), clip_y(py(s.y[i])), s.color, 2);
    if (s.x.size() == 1) c.fill(clip_x(px(s.x[0])) - 2, clip_y(py(s.y[0])) - 2, 5, 5, s.color);
    if (s.mark_last_best) ring(c, px(s.best_x), py(s.best_y), 6, s.color);
  }
  // Legend.
  const int lx = kLeft + kAxisWidth + 30;
  int ly = top;
  c.text(lx, ly, "legend", black, 2);
  ly += Canvas::line_height(2) + 4;
  for (const PlotSeries& s : p.series) {
    c.fill(lx, ly + 3, 24, 4, s.color);
    c.text(lx + 32, ly, s.label, black, 1);
    ly += Canvas::line_height(1) + 6;
  }
  ly += 6;
  c.text(lx, ly, "rings: each curve's best F1", grey, 1);
  return c;
}

Status write_plot(const std::string& path, const Plot& plot) { return draw_plot(plot).write_png(path); }

}  // namespace trailnav::cli
