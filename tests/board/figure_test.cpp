// The pictures people look at: the pixel font, the legend, the scale bar and
// the PNG they end up in.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include "figure.hpp"
#include "font.hpp"

namespace trailnav::cli {
namespace {

std::vector<std::uint8_t> glyph_bits(char c) {
  std::vector<std::uint8_t> rows;
  for (int r = 0; r < static_cast<int>(kGlyphHeight); ++r) rows.push_back(glyph_row(c, r));
  return rows;
}

TEST(Font, EveryPrintableAsciiCharacterHasItsOwnGlyph) {
  std::set<std::vector<std::uint8_t>> seen;
  for (int c = 32; c <= 126; ++c) {
    ASSERT_TRUE(glyph_defined(static_cast<char>(c))) << "character " << c;
    const auto bits = glyph_bits(static_cast<char>(c));
    int set = 0;
    for (std::uint8_t b : bits) {
      EXPECT_EQ(b & ~0x1Fu, 0u) << "glyph " << static_cast<char>(c) << " wider than 5 pixels";
      set += __builtin_popcount(b);
    }
    if (c == ' ') {
      EXPECT_EQ(set, 0);
    } else {
      EXPECT_GT(set, 0) << "glyph '" << static_cast<char>(c) << "' is empty";
    }
    EXPECT_TRUE(seen.insert(bits).second) << "glyph '" << static_cast<char>(c) << "' looks like another";
  }
}

TEST(Font, CharactersOutsidePrintableAsciiAreDrawnAsAQuestionMark) {
  EXPECT_FALSE(glyph_defined('\n'));
  EXPECT_FALSE(glyph_defined(static_cast<char>(0xC2)));
  EXPECT_EQ(glyph_bits('\t'), glyph_bits('?'));
  EXPECT_EQ(glyph_bits(static_cast<char>(0xB5)), glyph_bits('?'));
  EXPECT_EQ(glyph_row('A', -1), 0);
  EXPECT_EQ(glyph_row('A', static_cast<int>(kGlyphHeight)), 0);
}

TEST(Figure, TextIsWrappedAtSpacesWithoutLosingAWord) {
  const std::string s = "the obstacle map of trailnav/obstacle_map after revolution 1234 averyveryverylongword";
  for (int width : {8, 12, 20, 40}) {
    const auto lines = wrap_text(s, width);
    std::string joined;
    for (const auto& l : lines) {
      EXPECT_LE(static_cast<int>(l.size()), width) << l;
      EXPECT_FALSE(l.empty());
      joined += l;
    }
    std::string no_spaces;
    for (char c : s) {
      if (c != ' ') no_spaces += c;
    }
    std::string joined_no_spaces;
    for (char c : joined) {
      if (c != ' ') joined_no_spaces += c;
    }
    EXPECT_EQ(joined_no_spaces, no_spaces) << "width " << width;
  }
  EXPECT_TRUE(wrap_text("", 10).empty());
  EXPECT_EQ(wrap_text("  two   words ", 20), (std::vector<std::string>{"two words"}));
}

TEST(Figure, TheScaleBarIsTheLongestRoundLengthThatFits) {
  EXPECT_DOUBLE_EQ(scale_bar_metres(0.2, 276), 50.0);   // 55.2 m fit
  EXPECT_DOUBLE_EQ(scale_bar_metres(0.1, 276), 20.0);   // 27.6 m
  EXPECT_DOUBLE_EQ(scale_bar_metres(0.1, 100), 10.0);   // exactly 10 m
  EXPECT_DOUBLE_EQ(scale_bar_metres(0.05, 276), 10.0);  // 13.8 m
  EXPECT_DOUBLE_EQ(scale_bar_metres(1.0, 276), 200.0);
  EXPECT_DOUBLE_EQ(scale_bar_metres(0.001, 276), 0.2);  // 27.6 cm
  EXPECT_EQ(scale_bar_metres(0.0, 276), 0.0);
  EXPECT_EQ(scale_bar_metres(-1.0, 276), 0.0);
  EXPECT_EQ(scale_bar_metres(std::nan(""), 276), 0.0);
  EXPECT_EQ(scale_bar_metres(0.1, 0), 0.0);
}

std::vector<std::uint8_t> checkerboard(int w, int h) {
  const auto uw = static_cast<std::size_t>(w);
  std::vector<std::uint8_t> rgb(uw * static_cast<std::size_t>(h) * 3);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      std::uint8_t* p = &rgb[(static_cast<std::size_t>(y) * uw + static_cast<std::size_t>(x)) * 3];
      p[0] = static_cast<std::uint8_t>(x);
      p[1] = static_cast<std::uint8_t>(y);
      p[2] = static_cast<std::uint8_t>((x + y) % 2 ? 200 : 10);
    }
  }
  return rgb;
}

TEST(Figure, TheMapIsEnlargedByAWholeFactorAndThePanelMeasuresIt) {
  const int w = 300, h = 200;
  const auto rgb = checkerboard(w, h);
  MapFigure f;
  f.title = "obstacle map";
  f.notes = {"frame odom", "300 x 200 cells of 0.20 m"};
  f.legend = {{{60, 70, 90}, "unknown"}, {{255, 255, 255}, "free"}, {{0, 0, 0}, "occupied"}};
  f.metres_per_pixel = 0.2;
  FigureLayout layout;
  const Canvas c = compose_map_figure(rgb, w, h, f, layout);
  ASSERT_EQ(layout.zoom, 2);  // 300 px -> 600, within 640
  EXPECT_EQ(c.width(), 600 + kPanelWidth);
  EXPECT_GE(c.height(), 400);
  // Every map pixel is a 2 x 2 square of its colour.
  for (int y = 0; y < h; y += 7) {
    for (int x = 0; x < w; x += 11) {
      const std::uint8_t* p = &rgb[(static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x)) * 3];
      const Rgb want{p[0], p[1], p[2]};
      for (int dy = 0; dy < 2; ++dy) {
        for (int dx = 0; dx < 2; ++dx) ASSERT_EQ(c.at(2 * x + dx, 2 * y + dy), want) << x << "," << y;
      }
    }
  }
  // The swatches show the legend's colours.
  ASSERT_EQ(layout.swatch_y.size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(c.at(layout.swatch_x + 8, layout.swatch_y[i] + 8), f.legend[i].color) << i;
  }
  EXPECT_GE(layout.swatch_x, 600);
  // The bar: a round length, as long in drawn pixels as it is in metres at 0.1 m per drawn pixel.
  EXPECT_DOUBLE_EQ(layout.bar_metres, 20.0);
  EXPECT_EQ(layout.bar_pixels, 200);
  EXPECT_EQ(c.at(layout.bar_x, layout.bar_y + 2), (Rgb{25, 25, 30}));
  EXPECT_GT(layout.bar_y, layout.swatch_y.back());
  // The title is drawn: dark pixels in its first line.
  int ink = 0;
  for (int y = 12; y < 12 + 18; ++y) {
    for (int x = 612; x < 612 + Canvas::text_width("obstacle map", 2); ++x) ink += c.at(x, y) == Rgb{25, 25, 30} ? 1 : 0;
  }
  EXPECT_GT(ink, 100);
}

TEST(Figure, ALargeMapIsNotShrunkAndTheBarFollowsItsResolution) {
  const auto rgb = checkerboard(700, 50);
  MapFigure f;
  f.title = "overview";
  f.metres_per_pixel = 0.5;
  FigureLayout layout;
  const Canvas c = compose_map_figure(rgb, 700, 50, f, layout);
  EXPECT_EQ(layout.zoom, 1);
  EXPECT_EQ(c.width(), 700 + kPanelWidth);
  EXPECT_DOUBLE_EQ(layout.bar_metres, 100.0);  // 276 px x 0.5 m = 138 m
  EXPECT_EQ(layout.bar_pixels, 200);
}

std::uint32_t be32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | p[3];
}

TEST(Figure, IsWrittenAsAnRgbPngOfTheComposedSize) {
  const auto rgb = checkerboard(120, 90);
  MapFigure f;
  f.title = "a map";
  f.legend = {{{1, 2, 3}, "one"}};
  f.metres_per_pixel = 0.25;
  const std::string path = (std::filesystem::temp_directory_path() / "trailnav-figure-test.png").string();
  ASSERT_TRUE(write_map_figure(path, rgb, 120, 90, f));
  std::ifstream in(path, std::ios::binary);
  std::vector<unsigned char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::filesystem::remove(path);
  ASSERT_GT(bytes.size(), 33u);
  EXPECT_EQ(bytes[1], 'P');
  EXPECT_EQ(std::string(bytes.begin() + 12, bytes.begin() + 16), "IHDR");
  const Canvas c = compose_map_figure(rgb, 120, 90, f);
  EXPECT_EQ(be32(&bytes[16]), static_cast<std::uint32_t>(c.width()));
  EXPECT_EQ(be32(&bytes[20]), static_cast<std::uint32_t>(c.height()));
  EXPECT_EQ(bytes[24], 8);  // bit depth
  EXPECT_EQ(bytes[25], 2);  // RGB
  EXPECT_FALSE(write_map_figure("/nonexistent-dir/x.png", rgb, 120, 90, f));
}

}  // namespace
}  // namespace trailnav::cli
