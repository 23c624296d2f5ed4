// A small pixel font for the text on trailnav's pictures (legends, scale
// bars, titles): printable ASCII, each glyph 5 pixels wide and 9 high (7 from
// the cap line to the baseline, 2 for descenders). Anything else is drawn as
// '?'. Not for real-time threads.
#pragma once

#include <cstddef>
#include <cstdint>

namespace trailnav::cli {

inline constexpr std::size_t kGlyphWidth = 5;
inline constexpr std::size_t kGlyphHeight = 9;

// True for the characters the font draws (' ' to '~').
bool glyph_defined(char c) noexcept;
// Row `row` (0 = top) of the glyph as a bit mask, bit 4 the leftmost pixel;
// 0 outside the glyph.
std::uint8_t glyph_row(char c, int row) noexcept;

}  // namespace trailnav::cli
