#include "builtin_models.hpp"

#define TN_MODEL(name)                                                     \
  extern "C" const unsigned char trailnav_builtin_terrain_model_##name[]; \
  extern "C" const unsigned char trailnav_builtin_terrain_model_##name##_end[];
TN_MODEL(vlp16)
TN_MODEL(vlp32c)
TN_MODEL(hdl32e)
TN_MODEL(hdl64e)
TN_MODEL(trav_large)
#undef TN_MODEL

namespace trailnav::cli {
namespace {

std::span<const std::uint8_t> bytes(const unsigned char* begin, const unsigned char* end) noexcept {
  return {begin, static_cast<std::size_t>(end - begin)};
}

}  // namespace

std::span<const std::uint8_t> builtin_terrain_model(velodyne::Model lidar) noexcept {
  switch (lidar) {
    case velodyne::Model::vlp16: return bytes(trailnav_builtin_terrain_model_vlp16, trailnav_builtin_terrain_model_vlp16_end);
    case velodyne::Model::vlp32c: return bytes(trailnav_builtin_terrain_model_vlp32c, trailnav_builtin_terrain_model_vlp32c_end);
    case velodyne::Model::hdl32e: return bytes(trailnav_builtin_terrain_model_hdl32e, trailnav_builtin_terrain_model_hdl32e_end);
    case velodyne::Model::hdl64e: return bytes(trailnav_builtin_terrain_model_hdl64e, trailnav_builtin_terrain_model_hdl64e_end);
    case velodyne::Model::vlp16_hires: return {};
  }
  return {};
}

std::span<const std::uint8_t> builtin_traversability_model() noexcept {
  return bytes(trailnav_builtin_terrain_model_trav_large, trailnav_builtin_terrain_model_trav_large_end);
}

}  // namespace trailnav::cli
