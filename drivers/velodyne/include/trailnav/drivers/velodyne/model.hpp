// Velodyne sensor models and their firing geometry and timing, as given in
// the manufacturer's user manuals.
#pragma once

#include <cstdint>
#include <optional>
#include <string_view>

namespace trailnav::velodyne {

enum class Model : std::uint8_t { vlp16, vlp16_hires, vlp32c, hdl32e, hdl64e };

enum class ReturnMode : std::uint8_t { strongest, last, dual };

struct ModelInfo {
  Model model;
  std::string_view name;       // as users write it: "VLP-16", "HDL-64E", ...
  int lasers;                  // lasers in the sensor
  std::uint8_t product_id;     // factory byte 1205; 0 where the sensor sends none (HDL-64E)
  double distance_resolution;  // metres per distance count
  // Timing. Blocks that fire at the same instant (dual-return pairs, HDL-64E
  // upper/lower pairs) form a group; groups follow each other every
  // group_period_us. Within a group, a firing's offset is
  // sequence * sequence_period_us + (laser_in_block / lasers_per_step) * step_us.
  double group_period_us;
  int sequences_per_block;    // VLP-16: two firing sequences of 16 lasers per block
  double sequence_period_us;  // VLP-16: 55.296
  double step_us;             // time between consecutive firings in a sequence
  int lasers_per_step;        // lasers fired together (VLP-32C fires pairs)
};

const ModelInfo& model_info(Model model) noexcept;

// Parses "VLP-16", "VLP-16-HiRes", "VLP-32C", "HDL-32E", "HDL-64E" (case-insensitive,
// dashes optional).
std::optional<Model> parse_model(std::string_view text) noexcept;

// The model named by factory byte 1205 of a data packet, if it is one we know.
std::optional<Model> model_from_product_id(std::uint8_t id) noexcept;
// Return mode from factory byte 1204 (0x37 strongest, 0x38 last, 0x39 dual).
std::optional<ReturnMode> return_mode_from_byte(std::uint8_t b) noexcept;

const char* return_mode_name(ReturnMode mode) noexcept;

}  // namespace trailnav::velodyne
