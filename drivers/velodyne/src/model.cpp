#include "trailnav/drivers/velodyne/model.hpp"

#include <array>
#include <cctype>
#include <string>

namespace trailnav::velodyne {
namespace {

// Timing from the user manuals: VLP-16 fires one laser every 2.304 us and a
// 16-laser sequence every 55.296 us, two sequences per block; the VLP-32C
// fires laser pairs every 2.304 us, one block per 55.296 us; the HDL-32E fires
// one laser every 1.152 us, one block per 46.08 us. The HDL-64E fires an upper
// and a lower laser together; its manual gives no per-laser table, so the
// 32 firings of a block pair are spread evenly over the 48 us a pair takes at
// its nominal 1.33 M points/s.
constexpr std::array<ModelInfo, 5> kModels = {{
    {Model::vlp16, "VLP-16", 16, 0x22, 0.002, 110.592, 2, 55.296, 2.304, 1},
    {Model::vlp16_hires, "VLP-16-HiRes", 16, 0x24, 0.002, 110.592, 2, 55.296, 2.304, 1},
    {Model::vlp32c, "VLP-32C", 32, 0x28, 0.004, 55.296, 1, 55.296, 2.304, 2},
    {Model::hdl32e, "HDL-32E", 32, 0x21, 0.002, 46.08, 1, 46.08, 1.152, 1},
    {Model::hdl64e, "HDL-64E", 64, 0x00, 0.002, 48.0, 1, 48.0, 1.5, 1},
}};

std::string normalise(std::string_view text) {
  std::string out;
  for (char c : text) {
    if (c == '-' || c == '_' || c == ' ') continue;
    out.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
  }
  return out;
}

}  // namespace

const ModelInfo& model_info(Model model) noexcept { return kModels[static_cast<std::size_t>(model)]; }

std::optional<Model> parse_model(std::string_view text) noexcept {
  const std::string n = normalise(text);
  for (const ModelInfo& m : kModels) {
    if (normalise(m.name) == n) return m.model;
  }
  if (n == "vlp16hires" || n == "puckhires") return Model::vlp16_hires;
  if (n == "hdl64" || n == "hdl64es2" || n == "hdl64es21" || n == "hdl64es3") return Model::hdl64e;
  return std::nullopt;
}

std::optional<Model> model_from_product_id(std::uint8_t id) noexcept {
  for (const ModelInfo& m : kModels) {
    if (m.product_id != 0 && m.product_id == id) return m.model;
  }
  if (id == 0x23) return Model::vlp16;  // Puck LITE: VLP-16 geometry
  return std::nullopt;
}

std::optional<ReturnMode> return_mode_from_byte(std::uint8_t b) noexcept {
  switch (b) {
    case 0x37: return ReturnMode::strongest;
    case 0x38: return ReturnMode::last;
    case 0x39: return ReturnMode::dual;
    default: return std::nullopt;
  }
}

const char* return_mode_name(ReturnMode mode) noexcept {
  switch (mode) {
    case ReturnMode::strongest: return "strongest";
    case ReturnMode::last: return "last";
    case ReturnMode::dual: return "dual";
  }
  return "?";
}

}  // namespace trailnav::velodyne
