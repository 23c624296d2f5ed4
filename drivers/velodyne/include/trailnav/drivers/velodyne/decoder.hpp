// Decodes Velodyne data packets into points. A pure parser: no I/O, no
// allocation after construction, and no transcendental function per point —
// the trigonometry of every azimuth and laser is tabulated at construction.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "trailnav/drivers/velodyne/calibration.hpp"
#include "trailnav/drivers/velodyne/model.hpp"
#include "trailnav/drivers/velodyne/packet.hpp"

namespace trailnav::velodyne {

// How a point relates to the returns of its firing.
enum class ReturnKind : std::uint8_t {
  strongest = 0,       // single-return packet, strongest mode
  last = 1,            // single-return packet, last mode
  dual_last = 2,       // dual-return packet: the last return
  dual_strongest = 3,  // dual-return packet: the strongest (or second strongest) return
  dual_both = 4,       // dual-return packet whose two returns are the same: one point
};

// Which returns of a dual-return packet to keep.
enum class ReturnSelection : std::uint8_t { all, strongest, last };

// How the azimuth of the firings in a packet's last firing group is found.
// The sensor only reports each group's start azimuth; the advance during a
// group is the gap to the next group, unknown for the last one.
enum class LastGroupAzimuth : std::uint8_t {
  extrapolate,  // assume the previous group's advance (default; as ROS velodyne_pointcloud)
  hold,         // keep the group's start azimuth for all its firings (as tier4/nebula)
};

struct DecoderOptions {
  ReturnSelection selection = ReturnSelection::all;
  ReturnMode hdl64e_mode = ReturnMode::strongest;  // HDL-64E packets do not state it; dual unsupported
  LastGroupAzimuth last_group = LastGroupAzimuth::extrapolate;
};

// One return. Frame: the sensor's, x forward (azimuth 0), y left, z up, as
// in ROS velodyne_pointcloud.
struct Point {
  float x = 0.0f;          // m
  float y = 0.0f;          // m
  float z = 0.0f;          // m
  float distance = 0.0f;   // m, after the laser's distance correction
  float azimuth = 0.0f;    // rad in [0, 2pi), clockwise seen from above, the laser's own pointing direction
  float intensity = 0.0f;  // 0..255 (HDL-64E: after the focal intensity correction)
  float time = 0.0f;       // s, firing time after the packet's first firing
  std::uint16_t ring = 0;  // laser index sorted by elevation, 0 = lowest
  std::uint8_t laser = 0;  // laser id as in the packet and calibration
  ReturnKind kind = ReturnKind::strongest;
  std::uint8_t sequence = 0;  // firing sequence within the packet (see PacketInfo)
};

enum class PacketError : std::uint8_t {
  none,
  wrong_size,          // not 1206 bytes
  bad_block_flag,      // a block flag other than 0xFFEE (or 0xFFDD on an HDL-64E)
  bad_azimuth,         // an azimuth of 36000 or more
  unknown_return_mode, // factory byte 1204 is not 0x37, 0x38 or 0x39
  model_mismatch,      // product id says another model than the configured one
};

const char* packet_error_name(PacketError error) noexcept;

// Firing sequences a packet can hold: 12 blocks of two VLP-16 sequences.
inline constexpr int kMaxSequencesPerPacket = 24;

struct PacketInfo {
  PacketError error = PacketError::none;
  std::uint32_t timestamp_us = 0;  // microseconds past the hour, of the first firing
  ReturnMode mode = ReturnMode::strongest;
  std::uint16_t first_azimuth = 0;  // hundredths of a degree, first block
  std::uint16_t last_azimuth = 0;   // hundredths of a degree, last block
  int points = 0;                   // points written
  int zero_returns = 0;             // firings without a return (distance 0)
  // Firing sequences (all lasers firing once) in time order. Both blocks of a
  // dual-return pair, and both HDL-64E laser blocks, share their sequences.
  int sequences = 0;
  std::array<float, kMaxSequencesPerPacket> sequence_azimuth{};  // hundredths of a degree at the sequence's start, [0, 36000)
  std::array<float, kMaxSequencesPerPacket> sequence_time_us{};  // after the packet's first firing
};

// How decode() computes the points. `blocks` takes a block with at least 24
// returns whole, the laser constants laid out by return slot, four at a time
// (SSE2, on x86-64; elsewhere, for now, it is `per_point`), and sparser blocks
// one return after another; `per_point` every return one after another. Both give
// bit-identical points (test); `blocks` a full HDL-64E packet in about two
// thirds of the time (trailnav_velodyne_bench).
enum class DecodeKernel : std::uint8_t { blocks, per_point };

class PacketDecoder {
 public:
  // Checks the calibration against the model and tabulates everything.
  struct Created;
  static Created create(Model model, const Calibration& calibration, const DecoderOptions& options = {});

  const ModelInfo& model() const noexcept { return *info_; }
  const Calibration& calibration() const noexcept { return calibration_; }
  double distance_resolution() const noexcept { return resolution_; }
  // Ring of each laser id.
  std::span<const std::uint16_t> rings() const noexcept { return {rings_.data(), rings_.size()}; }

  // Decodes one packet into `out`, which must hold kMaxPointsPerPacket points.
  PacketInfo decode(std::span<const std::uint8_t> payload, std::span<Point> out,
                    DecodeKernel kernel = DecodeKernel::blocks) const noexcept;

  // The point that laser `laser` reports at firing azimuth `azimuth`
  // (hundredths of a degree) for a raw distance and intensity: exactly what
  // decode() computes. For tools that must predict the decoder (the
  // simulator); time, sequence and kind are left at zero.
  Point point_of(int laser, float azimuth, std::uint16_t raw, std::uint8_t intensity) const noexcept;
  // Time of return slot k's firing after its firing group's start (us).
  float firing_offset_us(int slot) const noexcept { return firing_time_us_[static_cast<std::size_t>(slot)]; }

 private:
  PacketDecoder() = default;

  struct LaserTable {
    float cos_vert, sin_vert;
    float cos_rot, sin_rot;
    float rot;  // rad
    float dist_correction, dist_correction_x, dist_correction_y;
    float vert_offset, horiz_offset;
    bool two_pt;
    bool intensity_correction;
    float focal_offset, focal_slope;
    float min_intensity, max_intensity;
  };

  // One return's position, distance, pointing and intensity.
  void place(const LaserTable& t, float azimuth, std::uint16_t raw, std::uint8_t raw_intensity, Point& pt) const noexcept;

  // The lasers' constants by return slot of an upper (0) or lower (1)
  // block, for DecodeKernel::blocks. A correction a laser does not have is
  // written so that it changes nothing, exactly: the two-point distances
  // equal to the plain one, a focal slope of 0 and the limits 0 and 255.
  struct BlockTable {
    std::array<float, kReturnsPerBlock> cos_vert, sin_vert, cos_rot, sin_rot, rot;
    std::array<float, kReturnsPerBlock> dist_correction, dist_correction_x, dist_correction_y;
    std::array<float, kReturnsPerBlock> vert_offset, horiz_offset;
    std::array<float, kReturnsPerBlock> focal_offset, focal_slope, min_intensity, max_intensity;
    bool corrections = false;  // some laser has the two-point or the intensity correction
  };
  // The returns of one block, slot by slot.
  struct BlockReturns {
    std::array<float, kReturnsPerBlock> azimuth, raw, intensity;  // in
    std::array<float, kReturnsPerBlock> x, y, z, distance, pointing, corrected;  // out
    // Slot k's point: the pointing wrapped into [0, 2pi), the intensity limited.
    void finish(const BlockTable& t, std::size_t k, Point& pt) const noexcept;
  };
  void place_block(const BlockTable& t, BlockReturns& r) const noexcept;  // SSE2 builds only

  const ModelInfo* info_ = nullptr;
  Calibration calibration_;
  DecoderOptions options_;
  double resolution_ = 0.002;
  std::vector<LaserTable> lasers_;
  std::vector<std::uint16_t> rings_;
  std::array<BlockTable, 2> block_tables_{};
  std::vector<float> sin_table_;  // sin of hundredths of a degree, 0..36000
  std::vector<float> cos_table_;
  // Time of the firing of return slot k after its firing group's start (us).
  std::array<float, kReturnsPerBlock> firing_time_us_{};
};

struct PacketDecoder::Created {
  std::optional<PacketDecoder> decoder;
  std::string error;
};

}  // namespace trailnav::velodyne
