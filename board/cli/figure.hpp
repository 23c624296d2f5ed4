// Pictures a person can read: a map with a panel beside it holding a title,
// notes, a legend of its colours, a scale bar and a north arrow, drawn pixel
// by pixel (font.hpp) and written as PNG. Every map trailnav writes for
// people goes through here (obstacle and terrain maps from the demo, `echo`
// and `obstacles`, the simulator's overview). Not for real-time threads.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "trailnav/runtime/status.hpp"

namespace trailnav::cli {

struct Rgb {
  std::uint8_t r = 0, g = 0, b = 0;
  friend bool operator==(const Rgb&, const Rgb&) = default;
};

// An RGB picture, top row first. Drawing outside it is clipped.
class Canvas {
 public:
  Canvas(int width, int height, Rgb background);

  int width() const noexcept { return width_; }
  int height() const noexcept { return height_; }
  std::span<const std::uint8_t> pixels() const noexcept { return pixels_; }

  void set(int x, int y, Rgb c) noexcept;
  Rgb at(int x, int y) const noexcept;  // black outside
  void fill(int x, int y, int w, int h, Rgb c) noexcept;
  void outline(int x, int y, int w, int h, Rgb c) noexcept;  // one pixel wide
  // `rgb` (w x h, top row first) with its top-left at (x, y), each of its
  // pixels a zoom x zoom square.
  void draw_image(std::span<const std::uint8_t> rgb, int w, int h, int x, int y, int zoom) noexcept;
  // Text with the top-left of its first glyph's cell at (x, y), each font
  // pixel a scale x scale square; returns the x after the text.
  int text(int x, int y, std::string_view s, Rgb c, int scale = 1) noexcept;

  static int text_width(std::string_view s, int scale) noexcept;
  static int line_height(int scale) noexcept;

  Status write_png(const std::string& path) const;

 private:
  int width_;
  int height_;
  std::vector<std::uint8_t> pixels_;
};

// Breaks `s` at spaces into lines of at most `max_chars` characters (a word
// longer than that is cut).
std::vector<std::string> wrap_text(std::string_view s, int max_chars);

// The scale bar's length: the largest 1, 2 or 5 x 10^k metres whose bar is
// at most `max_pixels` long at `metres_per_pixel` (0 if none fits).
double scale_bar_metres(double metres_per_pixel, int max_pixels) noexcept;

struct LegendEntry {
  Rgb color;
  std::string label;
};

struct MapFigure {
  std::string title;
  std::vector<std::string> notes;    // lines under the title: what, when, counts
  std::vector<LegendEntry> legend;   // every colour the map uses
  double metres_per_pixel = 0.0;     // of the map as given; > 0 draws a scale bar
  bool north_up = true;              // draws a north arrow
};

// The map (w x h RGB, top row first), enlarged by a whole factor while its
// longer side stays within 640 pixels (never shrunk), with the panel on its
// right.
Canvas compose_map_figure(std::span<const std::uint8_t> rgb, int w, int h, const MapFigure& figure);
Status write_map_figure(const std::string& path, std::span<const std::uint8_t> rgb, int w, int h,
                        const MapFigure& figure);

// The panel's layout, for tests: the zoom of the map and where the scale bar
// was drawn (x, y of its left end, its length in pixels and metres).
struct FigureLayout {
  int zoom = 1;
  int map_width = 0, map_height = 0;  // after zoom
  int bar_x = 0, bar_y = 0, bar_pixels = 0;
  double bar_metres = 0.0;
  int swatch_x = 0;
  std::vector<int> swatch_y;  // top of each legend entry's swatch
};
inline constexpr int kPanelWidth = 300;
Canvas compose_map_figure(std::span<const std::uint8_t> rgb, int w, int h, const MapFigure& figure,
                          FigureLayout& layout);

}  // namespace trailnav::cli
