#include "figure.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "font.hpp"
#include "png.hpp"

namespace trailnav::cli {
namespace {

constexpr Rgb kPanel{246, 246, 243};
constexpr Rgb kInk{25, 25, 30};
constexpr Rgb kFaint{95, 95, 105};
constexpr Rgb kWhite{255, 255, 255};
constexpr int kMargin = 12;
constexpr int kMaxMapSide = 640;
constexpr int kTitleScale = 2;
constexpr int kNoteScale = 1;
constexpr int kLegendScale = 2;

}  // namespace

Canvas::Canvas(int width, int height, Rgb background)
    : width_(std::max(width, 1)), height_(std::max(height, 1)),
      pixels_(static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_) * 3) {
  fill(0, 0, width_, height_, background);
}

void Canvas::set(int x, int y, Rgb c) noexcept {
  if (x < 0 || y < 0 || x >= width_ || y >= height_) return;
  std::uint8_t* p = &pixels_[(static_cast<std::size_t>(y) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(x)) * 3];
  p[0] = c.r;
  p[1] = c.g;
  p[2] = c.b;
}

Rgb Canvas::at(int x, int y) const noexcept {
  if (x < 0 || y < 0 || x >= width_ || y >= height_) return {};
  const std::uint8_t* p =
      &pixels_[(static_cast<std::size_t>(y) * static_cast<std::size_t>(width_) + static_cast<std::size_t>(x)) * 3];
  return {p[0], p[1], p[2]};
}

void Canvas::fill(int x, int y, int w, int h, Rgb c) noexcept {
  const int x0 = std::max(x, 0), y0 = std::max(y, 0);
  const int x1 = std::min(x + w, width_), y1 = std::min(y + h, height_);
  for (int j = y0; j < y1; ++j) {
    for (int i = x0; i < x1; ++i) set(i, j, c);
  }
}

void Canvas::outline(int x, int y, int w, int h, Rgb c) noexcept {
  fill(x, y, w, 1, c);
  fill(x, y + h - 1, w, 1, c);
  fill(x, y, 1, h, c);
  fill(x + w - 1, y, 1, h, c);
}

void Canvas::draw_image(std::span<const std::uint8_t> rgb, int w, int h, int x, int y, int zoom) noexcept {
  if (w <= 0 || h <= 0 || zoom <= 0) return;
  if (rgb.size() < static_cast<std::size_t>(w) * static_cast<std::size_t>(h) * 3) return;
  for (int j = 0; j < h; ++j) {
    for (int i = 0; i < w; ++i) {
      const std::uint8_t* p = &rgb[(static_cast<std::size_t>(j) * static_cast<std::size_t>(w) + static_cast<std::size_t>(i)) * 3];
      fill(x + i * zoom, y + j * zoom, zoom, zoom, {p[0], p[1], p[2]});
    }
  }
}

int Canvas::text(int x, int y, std::string_view s, Rgb c, int scale) noexcept {
  scale = std::max(scale, 1);
  for (const char ch : s) {
    for (int row = 0; row < static_cast<int>(kGlyphHeight); ++row) {
      const std::uint8_t bits = glyph_row(ch, row);
      for (int col = 0; col < static_cast<int>(kGlyphWidth); ++col) {
        if (bits & (1u << (kGlyphWidth - 1 - static_cast<std::size_t>(col)))) {
          fill(x + col * scale, y + row * scale, scale, scale, c);
        }
      }
    }
    x += static_cast<int>(kGlyphWidth + 1) * scale;
  }
  return x;
}

int Canvas::text_width(std::string_view s, int scale) noexcept {
  scale = std::max(scale, 1);
  if (s.empty()) return 0;
  return static_cast<int>(s.size()) * static_cast<int>(kGlyphWidth + 1) * scale - scale;
}

int Canvas::line_height(int scale) noexcept { return (static_cast<int>(kGlyphHeight) + 2) * std::max(scale, 1); }

Status Canvas::write_png(const std::string& path) const {
  return cli::write_png(path, static_cast<std::uint32_t>(width_), static_cast<std::uint32_t>(height_), PngColor::rgb,
                        pixels_);
}

std::vector<std::string> wrap_text(std::string_view s, int max_chars) {
  max_chars = std::max(max_chars, 1);
  const auto limit = static_cast<std::size_t>(max_chars);
  std::vector<std::string> lines;
  std::string line;
  std::size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && s[i] == ' ') ++i;
    std::size_t j = i;
    while (j < s.size() && s[j] != ' ') ++j;
    std::string_view word = s.substr(i, j - i);
    i = j;
    if (word.empty()) break;
    while (word.size() > limit) {  // a word longer than a line: cut it
      if (!line.empty()) lines.push_back(std::move(line)), line.clear();
      lines.emplace_back(word.substr(0, limit));
      word.remove_prefix(limit);
    }
    if (word.empty()) continue;
    if (!line.empty() && line.size() + 1 + word.size() > limit) lines.push_back(std::move(line)), line.clear();
    if (!line.empty()) line += ' ';
    line += word;
  }
  if (!line.empty()) lines.push_back(std::move(line));
  return lines;
}

double scale_bar_metres(double metres_per_pixel, int max_pixels) noexcept {
  if (!(metres_per_pixel > 0.0) || !std::isfinite(metres_per_pixel) || max_pixels <= 0) return 0.0;
  const double longest = metres_per_pixel * max_pixels;
  double decade = std::pow(10.0, std::floor(std::log10(longest)));
  for (int k = 0; k < 2; ++k, decade /= 10.0) {  // guard the log's rounding at exact powers
    for (const double m : {5.0, 2.0, 1.0}) {
      const double metres = m * decade;
      if (metres <= longest * (1.0 + 1e-12)) return metres;
    }
  }
  return 0.0;
}

Canvas compose_map_figure(std::span<const std::uint8_t> rgb, int w, int h, const MapFigure& figure) {
  FigureLayout layout;
  return compose_map_figure(rgb, w, h, figure, layout);
}

Canvas compose_map_figure(std::span<const std::uint8_t> rgb, int w, int h, const MapFigure& figure,
                          FigureLayout& layout) {
  w = std::max(w, 1);
  h = std::max(h, 1);
  layout = {};
  layout.zoom = std::max(1, kMaxMapSide / std::max(w, h));
  layout.map_width = w * layout.zoom;
  layout.map_height = h * layout.zoom;

  // The panel's lines, to know its height first.
  const int inner = kPanelWidth - 2 * kMargin;
  const int title_chars = (inner + kTitleScale) / (static_cast<int>(kGlyphWidth + 1) * kTitleScale);
  const int note_chars = (inner + kNoteScale) / (static_cast<int>(kGlyphWidth + 1) * kNoteScale);
  const int swatch = Canvas::line_height(kLegendScale) - 4;
  const int label_chars = (inner - swatch - 8 + kLegendScale) / (static_cast<int>(kGlyphWidth + 1) * kLegendScale);
  std::vector<std::string> title = wrap_text(figure.title, title_chars);
  std::vector<std::string> notes;
  for (const std::string& n : figure.notes) {
    for (std::string& l : wrap_text(n, note_chars)) notes.push_back(std::move(l));
  }
  std::vector<std::vector<std::string>> labels;
  for (const LegendEntry& e : figure.legend) labels.push_back(wrap_text(e.label, label_chars));

  int panel_height = kMargin + static_cast<int>(title.size()) * Canvas::line_height(kTitleScale) + 6 +
                     static_cast<int>(notes.size()) * Canvas::line_height(kNoteScale) + 10;
  for (const auto& l : labels) panel_height += std::max<int>(1, static_cast<int>(l.size())) * Canvas::line_height(kLegendScale) + 4;
  const bool bar = figure.metres_per_pixel > 0.0;
  if (bar) panel_height += 12 + 10 + Canvas::line_height(kLegendScale);
  if (figure.north_up) panel_height += 70;
  panel_height += kMargin;

  Canvas canvas(layout.map_width + kPanelWidth, std::max(layout.map_height, panel_height), kPanel);
  canvas.draw_image(rgb, w, h, 0, 0, layout.zoom);
  canvas.fill(layout.map_width, 0, 1, canvas.height(), kFaint);

  const int x = layout.map_width + kMargin;
  int y = kMargin;
  for (const std::string& l : title) {
    canvas.text(x, y, l, kInk, kTitleScale);
    y += Canvas::line_height(kTitleScale);
  }
  y += 6;
  for (const std::string& l : notes) {
    canvas.text(x, y, l, kFaint, kNoteScale);
    y += Canvas::line_height(kNoteScale);
  }
  y += 10;
  layout.swatch_x = x;
  for (std::size_t i = 0; i < figure.legend.size(); ++i) {
    layout.swatch_y.push_back(y);
    canvas.fill(x, y, swatch, swatch, figure.legend[i].color);
    canvas.outline(x, y, swatch, swatch, kInk);
    int ly = y;
    for (const std::string& l : labels[i]) {
      canvas.text(x + swatch + 8, ly + 2, l, kInk, kLegendScale);
      ly += Canvas::line_height(kLegendScale);
    }
    y += std::max<int>(1, static_cast<int>(labels[i].size())) * Canvas::line_height(kLegendScale) + 4;
  }
  if (bar) {
    // The bar measures the map as drawn: metres per drawn pixel.
    const double per_pixel = figure.metres_per_pixel / layout.zoom;
    const double metres = scale_bar_metres(per_pixel, inner - 4);
    const int pixels = metres > 0.0 ? static_cast<int>(std::lround(metres / per_pixel)) : 0;
    y += 12;
    if (pixels > 0) {
      layout.bar_x = x;
      layout.bar_y = y;
      layout.bar_pixels = pixels;
      layout.bar_metres = metres;
      // Four segments, alternately dark and light, framed, with end ticks.
      for (int s = 0; s < 4; ++s) {
        const int a = pixels * s / 4, b = pixels * (s + 1) / 4;
        canvas.fill(x + a, y, b - a, 6, s % 2 == 0 ? kInk : kWhite);
      }
      canvas.outline(x, y, pixels, 6, kInk);
      canvas.fill(x, y - 3, 1, 12, kInk);
      canvas.fill(x + pixels - 1, y - 3, 1, 12, kInk);
      char label[48];
      if (metres >= 1.0) {
        std::snprintf(label, sizeof label, "%g m", metres);
      } else {
        std::snprintf(label, sizeof label, "%g cm", metres * 100.0);
      }
      canvas.text(x, y + 10, "0", kInk, kLegendScale);
      canvas.text(x + pixels - Canvas::text_width(label, kLegendScale), y + 10, label, kInk, kLegendScale);
    }
    y += 10 + Canvas::line_height(kLegendScale);
  }
  if (figure.north_up) {
    // An arrow pointing up, "N" at its head.
    const int cx = x + 20;
    y += 8;
    canvas.text(cx - Canvas::text_width("N", kLegendScale) / 2, y, "N", kInk, kLegendScale);
    const int top = y + Canvas::line_height(kLegendScale);
    for (int r = 0; r < 16; ++r) canvas.fill(cx - r / 2, top + r, 2 * (r / 2) + 1, 1, kInk);
    canvas.fill(cx - 1, top + 16, 3, 20, kInk);
  }
  return canvas;
}

Status write_map_figure(const std::string& path, std::span<const std::uint8_t> rgb, int w, int h,
                        const MapFigure& figure) {
  return compose_map_figure(rgb, w, h, figure).write_png(path);
}

}  // namespace trailnav::cli
