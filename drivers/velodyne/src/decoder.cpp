#include "trailnav/drivers/velodyne/decoder.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace trailnav::velodyne {
namespace {

constexpr int kAzimuthSteps = 36000;  // hundredths of a degree per turn
constexpr float kRadPerStep = static_cast<float>(std::numbers::pi / 18000.0);
constexpr float kTwoPi = static_cast<float>(2.0 * std::numbers::pi);
// DecodeKernel::blocks takes a block whole from this many returns on
// (trailnav_velodyne_bench: a whole block costs about 22 returns one by one).
constexpr int kBlockKernelMinReturns = 24;
#if defined(__SSE2__)
constexpr bool kHaveBlockKernel = true;
#else
constexpr bool kHaveBlockKernel = false;  // every return one by one
#endif
// Largest believable azimuth advance between two firing groups: 5 degrees.
constexpr int kMaxGroupGap = 500;

}  // namespace

const char* packet_error_name(PacketError error) noexcept {
  switch (error) {
    case PacketError::none: return "none";
    case PacketError::wrong_size: return "wrong_size";
    case PacketError::bad_block_flag: return "bad_block_flag";
    case PacketError::bad_azimuth: return "bad_azimuth";
    case PacketError::unknown_return_mode: return "unknown_return_mode";
    case PacketError::model_mismatch: return "model_mismatch";
  }
  return "?";
}

std::optional<Model> detect_model(std::span<const std::uint8_t> payload) noexcept {
  if (payload.size() != kDataPacketSize) return std::nullopt;
  for (int b = 0; b < kBlocksPerPacket; ++b) {
    if (read_u16(payload.data() + static_cast<std::size_t>(b) * kBlockSize) == kLowerBlockFlag) return Model::hdl64e;
  }
  return model_from_product_id(payload[kProductIdOffset]);
}

PositionError decode_position_packet(std::span<const std::uint8_t> payload, PositionPacket& out) noexcept {
  if (payload.size() != kPositionPacketSize) return PositionError::wrong_size;
  out.timestamp_us = read_u32(payload.data() + 198);
  if (out.timestamp_us >= kMicrosPerHour) return PositionError::bad_timestamp;
  const std::uint8_t pps = payload[202];
  if (pps > 3) return PositionError::bad_pps;
  out.pps = static_cast<PpsStatus>(pps);
  const auto* text = reinterpret_cast<const char*>(payload.data() + 206);
  std::size_t length = 0;
  const std::size_t limit = kPositionPacketSize - 206;
  while (length < limit && text[length] != '\0' && text[length] != '\r' && text[length] != '\n') ++length;
  out.nmea = std::string_view(text, length);
  return PositionError::none;
}

PacketDecoder::Created PacketDecoder::create(Model model, const Calibration& calibration, const DecoderOptions& options) {
  Created result;
  if (Status s = check_calibration(calibration, model); !s) {
    result.error = s.message();
    return result;
  }
  if (model == Model::hdl64e && options.hdl64e_mode == ReturnMode::dual) {
    result.error = "dual-return mode is not supported for the HDL-64E yet; set it to strongest or last";
    return result;
  }
  PacketDecoder d;
  d.info_ = &model_info(model);
  d.calibration_ = calibration;
  d.options_ = options;
  d.resolution_ = calibration.distance_resolution.value_or(d.info_->distance_resolution);

  d.sin_table_.resize(kAzimuthSteps + 1);
  d.cos_table_.resize(kAzimuthSteps + 1);
  for (int i = 0; i <= kAzimuthSteps; ++i) {
    const double a = static_cast<double>(i) * std::numbers::pi / 18000.0;
    d.sin_table_[static_cast<std::size_t>(i)] = static_cast<float>(std::sin(a));
    d.cos_table_[static_cast<std::size_t>(i)] = static_cast<float>(std::cos(a));
  }

  for (const LaserCorrection& c : calibration.lasers) {
    LaserTable t{};
    t.cos_vert = static_cast<float>(std::cos(c.vert_correction));
    t.sin_vert = static_cast<float>(std::sin(c.vert_correction));
    t.cos_rot = static_cast<float>(std::cos(c.rot_correction));
    t.sin_rot = static_cast<float>(std::sin(c.rot_correction));
    t.rot = static_cast<float>(c.rot_correction);
    t.dist_correction = static_cast<float>(c.dist_correction);
    t.dist_correction_x = static_cast<float>(c.dist_correction_x);
    t.dist_correction_y = static_cast<float>(c.dist_correction_y);
    t.vert_offset = static_cast<float>(c.vert_offset_correction);
    t.horiz_offset = static_cast<float>(c.horiz_offset_correction);
    t.two_pt = c.two_pt_correction;
    // Intensity correction of the HDL-64E manual, with the focal distance in
    // centimetres over the 131 m (13100 cm) maximum range.
    const double focal_cm = c.focal_distance * 100.0;
    t.focal_offset = static_cast<float>(256.0 * (1.0 - focal_cm / 13100.0) * (1.0 - focal_cm / 13100.0));
    t.focal_slope = static_cast<float>(c.focal_slope);
    t.intensity_correction = c.focal_slope != 0.0 || c.min_intensity != 0 || c.max_intensity != 255;
    t.min_intensity = static_cast<float>(c.min_intensity);
    t.max_intensity = static_cast<float>(c.max_intensity);
    d.lasers_.push_back(t);
  }

  for (int lower = 0; lower < 2; ++lower) {
    BlockTable& b = d.block_tables_[static_cast<std::size_t>(lower)];
    const int lasers_per_sequence = kReturnsPerBlock / d.info_->sequences_per_block;
    for (int k = 0; k < kReturnsPerBlock; ++k) {
      const auto laser = static_cast<std::size_t>((lower != 0 ? 32 : 0) + k % lasers_per_sequence);
      if (laser >= d.lasers_.size()) break;  // no lower block on this model
      const LaserTable& t = d.lasers_[laser];
      const auto i = static_cast<std::size_t>(k);
      b.cos_vert[i] = t.cos_vert;
      b.sin_vert[i] = t.sin_vert;
      b.cos_rot[i] = t.cos_rot;
      b.sin_rot[i] = t.sin_rot;
      b.rot[i] = t.rot;
      b.dist_correction[i] = t.dist_correction;
      b.dist_correction_x[i] = t.two_pt ? t.dist_correction_x : t.dist_correction;
      b.dist_correction_y[i] = t.two_pt ? t.dist_correction_y : t.dist_correction;
      b.vert_offset[i] = t.vert_offset;
      b.horiz_offset[i] = t.horiz_offset;
      b.focal_offset[i] = t.intensity_correction ? t.focal_offset : 0.0f;
      b.focal_slope[i] = t.intensity_correction ? t.focal_slope : 0.0f;
      b.min_intensity[i] = t.intensity_correction ? t.min_intensity : 0.0f;
      b.max_intensity[i] = t.intensity_correction ? t.max_intensity : 255.0f;
      b.corrections = b.corrections || t.two_pt || t.intensity_correction;
    }
  }

  // Rings: lasers sorted by elevation, lowest first (ties by id).
  std::vector<int> order(calibration.lasers.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return calibration.lasers[static_cast<std::size_t>(a)].vert_correction <
           calibration.lasers[static_cast<std::size_t>(b)].vert_correction;
  });
  d.rings_.resize(order.size());
  for (std::size_t r = 0; r < order.size(); ++r) d.rings_[static_cast<std::size_t>(order[r])] = static_cast<std::uint16_t>(r);

  const ModelInfo& m = *d.info_;
  for (int k = 0; k < kReturnsPerBlock; ++k) {
    const int lasers_per_sequence = kReturnsPerBlock / m.sequences_per_block;
    const int sequence = k / lasers_per_sequence;
    const int in_sequence = k % lasers_per_sequence;
    d.firing_time_us_[static_cast<std::size_t>(k)] =
        static_cast<float>(sequence * m.sequence_period_us + (in_sequence / m.lasers_per_step) * m.step_us);
  }
  result.decoder = std::move(d);
  return result;
}

void PacketDecoder::place(const LaserTable& t, float a, std::uint16_t raw, std::uint8_t raw_intensity,
                        Point& pt) const noexcept {
  // The laser's own rotation: table lookup plus a first-order step.
  const int ai = static_cast<int>(a);
  const float delta = (a - static_cast<float>(ai)) * kRadPerStep;
  const float s0 = sin_table_[static_cast<std::size_t>(ai)];
  const float c0 = cos_table_[static_cast<std::size_t>(ai)];
  const float sin_az = s0 + delta * c0;
  const float cos_az = c0 - delta * s0;
  const float sa = sin_az * t.cos_rot - cos_az * t.sin_rot;  // sin(azimuth - rot)
  const float ca = cos_az * t.cos_rot + sin_az * t.sin_rot;  // cos(azimuth - rot)

  const float distance = static_cast<float>(raw) * static_cast<float>(resolution_) + t.dist_correction;
  float distance_x = distance;
  float distance_y = distance;
  if (t.two_pt) {
    // Two-point distance correction of the HDL-64E, interpolated between
    // its calibration distances of 2.4 m (x), 1.93 m (y) and 25.04 m.
    const float xy0 = distance * t.cos_vert - t.vert_offset * t.sin_vert;
    const float xx = std::abs(xy0 * sa - t.horiz_offset * ca);
    const float yy = std::abs(xy0 * ca + t.horiz_offset * sa);
    distance_x += (t.dist_correction - t.dist_correction_x) * (xx - 2.4f) / (25.04f - 2.4f) + t.dist_correction_x - t.dist_correction;
    distance_y += (t.dist_correction - t.dist_correction_y) * (yy - 1.93f) / (25.04f - 1.93f) + t.dist_correction_y - t.dist_correction;
  }
  const float xy_x = distance_x * t.cos_vert - t.vert_offset * t.sin_vert;
  const float xy_y = distance_y * t.cos_vert - t.vert_offset * t.sin_vert;

  pt.x = xy_y * ca + t.horiz_offset * sa;
  pt.y = -(xy_x * sa - t.horiz_offset * ca);
  pt.z = distance_y * t.sin_vert + t.vert_offset * t.cos_vert;
  pt.distance = distance;
  float pointing = a * kRadPerStep - t.rot;
  if (pointing < 0.0f) pointing += kTwoPi;
  if (pointing >= kTwoPi) pointing -= kTwoPi;
  pt.azimuth = pointing;
  float intensity = raw_intensity;
  if (t.intensity_correction) {
    const float fall = 1.0f - static_cast<float>(raw) / 65535.0f;
    intensity += t.focal_slope * std::abs(t.focal_offset - 256.0f * fall * fall);
    intensity = std::clamp(intensity, t.min_intensity, t.max_intensity);
  }
  pt.intensity = intensity;
}

#if defined(__SSE2__)
void PacketDecoder::place_block(const BlockTable& t, BlockReturns& r) const noexcept {
  constexpr std::size_t n = kReturnsPerBlock;
  // The table lookups one by one, then the arithmetic of place() for four
  // slots at once (SSE2, part of every x86-64 CPU; without it decode() takes
  // every return one by one). Every step is place()'s, in its order and in
  // single precision, so that the points are the same bits (test).
  std::array<float, n> s0, c0, delta;
  for (std::size_t k = 0; k < n; ++k) {
    const int ai = static_cast<int>(r.azimuth[k]);
    delta[k] = (r.azimuth[k] - static_cast<float>(ai)) * kRadPerStep;
    s0[k] = sin_table_[static_cast<std::size_t>(ai)];
    c0[k] = cos_table_[static_cast<std::size_t>(ai)];
  }
  const __m128 res = _mm_set1_ps(static_cast<float>(resolution_));
  const __m128 sign = _mm_set1_ps(-0.0f);
  const __m128 two_pt_x = _mm_set1_ps(2.4f), span_x = _mm_set1_ps(25.04f - 2.4f);
  const __m128 two_pt_y = _mm_set1_ps(1.93f), span_y = _mm_set1_ps(25.04f - 1.93f);
  const __m128 rad = _mm_set1_ps(kRadPerStep), one = _mm_set1_ps(1.0f);
  const __m128 full = _mm_set1_ps(65535.0f), k256 = _mm_set1_ps(256.0f);
  if (!t.corrections) {
    // Without the HDL-64E's two-point and intensity corrections.
    for (std::size_t k = 0; k < n; k += 4) {
      const auto in = [k](const std::array<float, n>& a) noexcept { return _mm_loadu_ps(a.data() + k); };
      const __m128 vs0 = in(s0), vc0 = in(c0), vdelta = in(delta);
      const __m128 cos_rot = in(t.cos_rot), sin_rot = in(t.sin_rot), cos_vert = in(t.cos_vert), sin_vert = in(t.sin_vert);
      const __m128 vo = in(t.vert_offset), ho = in(t.horiz_offset);
      const __m128 sin_az = _mm_add_ps(vs0, _mm_mul_ps(vdelta, vc0));
      const __m128 cos_az = _mm_sub_ps(vc0, _mm_mul_ps(vdelta, vs0));
      const __m128 sa = _mm_sub_ps(_mm_mul_ps(sin_az, cos_rot), _mm_mul_ps(cos_az, sin_rot));
      const __m128 ca = _mm_add_ps(_mm_mul_ps(cos_az, cos_rot), _mm_mul_ps(sin_az, sin_rot));
      const __m128 distance = _mm_add_ps(_mm_mul_ps(in(r.raw), res), in(t.dist_correction));
      const __m128 xy = _mm_sub_ps(_mm_mul_ps(distance, cos_vert), _mm_mul_ps(vo, sin_vert));
      _mm_storeu_ps(r.x.data() + k, _mm_add_ps(_mm_mul_ps(xy, ca), _mm_mul_ps(ho, sa)));
      _mm_storeu_ps(r.y.data() + k, _mm_xor_ps(sign, _mm_sub_ps(_mm_mul_ps(xy, sa), _mm_mul_ps(ho, ca))));
      _mm_storeu_ps(r.z.data() + k, _mm_add_ps(_mm_mul_ps(distance, sin_vert), _mm_mul_ps(vo, cos_vert)));
      _mm_storeu_ps(r.distance.data() + k, distance);
      _mm_storeu_ps(r.pointing.data() + k, _mm_sub_ps(_mm_mul_ps(in(r.azimuth), rad), in(t.rot)));
      _mm_storeu_ps(r.corrected.data() + k, in(r.intensity));
    }
    return;
  }
  for (std::size_t k = 0; k < n; k += 4) {
    const auto in = [k](const std::array<float, n>& a) noexcept { return _mm_loadu_ps(a.data() + k); };
    const __m128 vs0 = in(s0), vc0 = in(c0), vdelta = in(delta);
    const __m128 cos_rot = in(t.cos_rot), sin_rot = in(t.sin_rot), cos_vert = in(t.cos_vert), sin_vert = in(t.sin_vert);
    const __m128 dc = in(t.dist_correction), dcx = in(t.dist_correction_x), dcy = in(t.dist_correction_y);
    const __m128 vo = in(t.vert_offset), ho = in(t.horiz_offset), raw = in(r.raw);
    const __m128 sin_az = _mm_add_ps(vs0, _mm_mul_ps(vdelta, vc0));
    const __m128 cos_az = _mm_sub_ps(vc0, _mm_mul_ps(vdelta, vs0));
    const __m128 sa = _mm_sub_ps(_mm_mul_ps(sin_az, cos_rot), _mm_mul_ps(cos_az, sin_rot));
    const __m128 ca = _mm_add_ps(_mm_mul_ps(cos_az, cos_rot), _mm_mul_ps(sin_az, sin_rot));
    const __m128 distance = _mm_add_ps(_mm_mul_ps(raw, res), dc);
    const __m128 vo_sin = _mm_mul_ps(vo, sin_vert);
    const __m128 xy0 = _mm_sub_ps(_mm_mul_ps(distance, cos_vert), vo_sin);
    const __m128 xx = _mm_andnot_ps(sign, _mm_sub_ps(_mm_mul_ps(xy0, sa), _mm_mul_ps(ho, ca)));
    const __m128 yy = _mm_andnot_ps(sign, _mm_add_ps(_mm_mul_ps(xy0, ca), _mm_mul_ps(ho, sa)));
    const __m128 distance_x = _mm_add_ps(
        distance,
        _mm_sub_ps(_mm_add_ps(_mm_div_ps(_mm_mul_ps(_mm_sub_ps(dc, dcx), _mm_sub_ps(xx, two_pt_x)), span_x), dcx), dc));
    const __m128 distance_y = _mm_add_ps(
        distance,
        _mm_sub_ps(_mm_add_ps(_mm_div_ps(_mm_mul_ps(_mm_sub_ps(dc, dcy), _mm_sub_ps(yy, two_pt_y)), span_y), dcy), dc));
    const __m128 xy_x = _mm_sub_ps(_mm_mul_ps(distance_x, cos_vert), vo_sin);
    const __m128 xy_y = _mm_sub_ps(_mm_mul_ps(distance_y, cos_vert), vo_sin);
    _mm_storeu_ps(r.x.data() + k, _mm_add_ps(_mm_mul_ps(xy_y, ca), _mm_mul_ps(ho, sa)));
    _mm_storeu_ps(r.y.data() + k, _mm_xor_ps(sign, _mm_sub_ps(_mm_mul_ps(xy_x, sa), _mm_mul_ps(ho, ca))));
    _mm_storeu_ps(r.z.data() + k, _mm_add_ps(_mm_mul_ps(distance_y, sin_vert), _mm_mul_ps(vo, cos_vert)));
    _mm_storeu_ps(r.distance.data() + k, distance);
    _mm_storeu_ps(r.pointing.data() + k, _mm_sub_ps(_mm_mul_ps(in(r.azimuth), rad), in(t.rot)));
    const __m128 fall = _mm_sub_ps(one, _mm_div_ps(raw, full));
    const __m128 focal = _mm_andnot_ps(sign, _mm_sub_ps(in(t.focal_offset), _mm_mul_ps(_mm_mul_ps(k256, fall), fall)));
    _mm_storeu_ps(r.corrected.data() + k, _mm_add_ps(in(r.intensity), _mm_mul_ps(in(t.focal_slope), focal)));
  }
}
#endif

void PacketDecoder::BlockReturns::finish(const BlockTable& t, std::size_t k, Point& pt) const noexcept {
  pt.x = x[k];
  pt.y = y[k];
  pt.z = z[k];
  pt.distance = distance[k];
  float p = pointing[k];
  if (p < 0.0f) p += kTwoPi;
  if (p >= kTwoPi) p -= kTwoPi;
  pt.azimuth = p;
  pt.intensity = std::clamp(corrected[k], t.min_intensity[k], t.max_intensity[k]);  // no-op without the correction
}

Point PacketDecoder::point_of(int laser, float azimuth, std::uint16_t raw, std::uint8_t intensity) const noexcept {
  Point pt;
  while (azimuth >= static_cast<float>(kAzimuthSteps)) azimuth -= static_cast<float>(kAzimuthSteps);
  while (azimuth < 0.0f) azimuth += static_cast<float>(kAzimuthSteps);
  place(lasers_[static_cast<std::size_t>(laser)], azimuth, raw, intensity, pt);
  pt.laser = static_cast<std::uint8_t>(laser);
  pt.ring = rings_[static_cast<std::size_t>(laser)];
  return pt;
}

PacketInfo PacketDecoder::decode(std::span<const std::uint8_t> payload, std::span<Point> out,
                                 DecodeKernel kernel) const noexcept {
  PacketInfo info;
  if (payload.size() != kDataPacketSize) {
    info.error = PacketError::wrong_size;
    return info;
  }
  const std::uint8_t* p = payload.data();
  const bool is64 = info_->model == Model::hdl64e;

  // Factory bytes (not sent by the HDL-64E, whose mode is configured).
  if (is64) {
    info.mode = options_.hdl64e_mode;
  } else {
    const auto mode = return_mode_from_byte(p[kReturnModeOffset]);
    if (!mode) {
      info.error = PacketError::unknown_return_mode;
      return info;
    }
    info.mode = *mode;
    const auto product = model_from_product_id(p[kProductIdOffset]);
    const bool compatible = !product || *product == info_->model ||
                            (info_->model == Model::vlp16_hires && *product == Model::vlp16) ||
                            (info_->model == Model::vlp16 && *product == Model::vlp16_hires);
    if (!compatible) {
      info.error = PacketError::model_mismatch;
      return info;
    }
  }

  // Validate every block before writing any point.
  std::array<std::uint16_t, kBlocksPerPacket> azimuth{};
  for (int b = 0; b < kBlocksPerPacket; ++b) {
    const std::uint8_t* block = p + static_cast<std::size_t>(b) * kBlockSize;
    const std::uint16_t flag = read_u16(block);
    if (flag != kUpperBlockFlag && !(is64 && flag == kLowerBlockFlag)) {
      info.error = PacketError::bad_block_flag;
      return info;
    }
    azimuth[static_cast<std::size_t>(b)] = read_u16(block + 2);
    if (azimuth[static_cast<std::size_t>(b)] >= kAzimuthSteps) {
      info.error = PacketError::bad_azimuth;
      return info;
    }
  }
  info.timestamp_us = read_u32(p + kTimestampOffset);
  info.first_azimuth = azimuth.front();
  info.last_azimuth = azimuth.back();

  const bool dual = info.mode == ReturnMode::dual;
  const int group_size = (dual ? 2 : 1) * (is64 ? 2 : 1);
  const int groups = kBlocksPerPacket / group_size;

  // Azimuth advance from each firing group to the next. The last group's is
  // unknown: the previous group's (extrapolate) or none (hold). An
  // implausible advance (corrupt azimuth) is replaced by the previous one.
  std::array<int, kBlocksPerPacket> gap{};
  int previous_gap = 0;
  for (int g = 0; g < groups; ++g) {
    int diff = previous_gap;
    if (g + 1 < groups) {
      diff = azimuth[static_cast<std::size_t>((g + 1) * group_size)] - azimuth[static_cast<std::size_t>(g * group_size)];
      if (diff < 0) diff += kAzimuthSteps;
      if (diff > kMaxGroupGap) diff = previous_gap;
    } else if (options_.last_group == LastGroupAzimuth::hold) {
      diff = 0;
    }
    gap[static_cast<std::size_t>(g)] = diff;
    previous_gap = diff;
  }

  const int sequences_per_block = info_->sequences_per_block;
  const float sequence_period = static_cast<float>(info_->sequence_period_us);
  info.sequences = groups * sequences_per_block;
  for (int s = 0; s < info.sequences; ++s) {
    const int g = s / sequences_per_block;
    const float offset_us = static_cast<float>(s % sequences_per_block) * sequence_period;
    float a = static_cast<float>(azimuth[static_cast<std::size_t>(g * group_size)]) +
              static_cast<float>(gap[static_cast<std::size_t>(g)]) * offset_us / static_cast<float>(info_->group_period_us);
    if (a >= static_cast<float>(kAzimuthSteps)) a -= static_cast<float>(kAzimuthSteps);
    info.sequence_azimuth[static_cast<std::size_t>(s)] = a;
    info.sequence_time_us[static_cast<std::size_t>(s)] = static_cast<float>(g) * static_cast<float>(info_->group_period_us) + offset_us;
  }

  const ReturnKind single_kind = info.mode == ReturnMode::last ? ReturnKind::last : ReturnKind::strongest;
  const float group_period = static_cast<float>(info_->group_period_us);
  const int lasers_per_sequence = kReturnsPerBlock / info_->sequences_per_block;
  int n = 0;

  for (int b = 0; b < kBlocksPerPacket; ++b) {
    const std::uint8_t* block = p + static_cast<std::size_t>(b) * kBlockSize;
    const int group = b / group_size;
    const bool lower = is64 && read_u16(block) == kLowerBlockFlag;
    // In a dual-return packet, even blocks of a pair carry the last return,
    // odd blocks the strongest.
    const bool second_of_pair = dual && (b % 2 == 1);
    ReturnKind kind = single_kind;
    if (dual) {
      kind = second_of_pair ? ReturnKind::dual_strongest : ReturnKind::dual_last;
      if (options_.selection == ReturnSelection::strongest && !second_of_pair) continue;
      if (options_.selection == ReturnSelection::last && second_of_pair) continue;
    }
    const float group_start_us = static_cast<float>(group) * group_period;
    const auto block_azimuth = static_cast<float>(azimuth[static_cast<std::size_t>(b)]);
    const auto group_gap = static_cast<float>(gap[static_cast<std::size_t>(group)]);
    // Azimuth of a slot's firing, interpolated over the group's advance.
    const auto slot_azimuth = [&](int k) noexcept {
      float a = block_azimuth + group_gap * (firing_time_us_[static_cast<std::size_t>(k)] / group_period);
      if (a >= static_cast<float>(kAzimuthSteps)) a -= static_cast<float>(kAzimuthSteps);
      return a;
    };
    // A block with few returns (sky, dust) goes one by one: the block
    // path costs about as much as 22 single returns, whatever it holds.
    int returns = 0;
    if (kHaveBlockKernel && kernel == DecodeKernel::blocks) {
      for (int k = 0; k < kReturnsPerBlock; ++k) returns += read_u16(block + 4 + static_cast<std::size_t>(k) * 3) != 0 ? 1 : 0;
    }
    const bool whole_block = returns >= kBlockKernelMinReturns;
    BlockReturns block_returns;
#if defined(__SSE2__)
    if (whole_block) {
      for (int k = 0; k < kReturnsPerBlock; ++k) {
        const std::uint8_t* ret = block + 4 + static_cast<std::size_t>(k) * 3;
        const auto i = static_cast<std::size_t>(k);
        block_returns.azimuth[i] = slot_azimuth(k);
        block_returns.raw[i] = static_cast<float>(read_u16(ret));
        block_returns.intensity[i] = static_cast<float>(ret[2]);
      }
      place_block(block_tables_[lower ? 1 : 0], block_returns);
    }
#endif

    for (int k = 0; k < kReturnsPerBlock; ++k) {
      const std::uint8_t* ret = block + 4 + static_cast<std::size_t>(k) * 3;
      const std::uint16_t raw = read_u16(ret);
      if (raw == 0) {
        ++info.zero_returns;
        continue;
      }
      ReturnKind point_kind = kind;
      if (dual && options_.selection == ReturnSelection::all) {
        // The sensor repeats a lone return in both blocks: keep it once.
        const std::uint8_t* other = p + static_cast<std::size_t>(second_of_pair ? b - 1 : b + 1) * kBlockSize + 4 +
                                    static_cast<std::size_t>(k) * 3;
        if (read_u16(other) == raw && other[2] == ret[2]) {
          if (second_of_pair) continue;
          point_kind = ReturnKind::dual_both;
        }
      }
      const int laser = (lower ? 32 : 0) + (k % lasers_per_sequence);
      const float t_in_group = firing_time_us_[static_cast<std::size_t>(k)];

      Point& pt = out[static_cast<std::size_t>(n++)];
      if (whole_block) {
        block_returns.finish(block_tables_[lower ? 1 : 0], static_cast<std::size_t>(k), pt);
      } else {
        place(lasers_[static_cast<std::size_t>(laser)], slot_azimuth(k), raw, ret[2], pt);
      }
      pt.time = (group_start_us + t_in_group) * 1e-6f;
      pt.ring = rings_[static_cast<std::size_t>(laser)];
      pt.laser = static_cast<std::uint8_t>(laser);
      pt.kind = point_kind;
      pt.sequence = static_cast<std::uint8_t>(group * sequences_per_block + k / lasers_per_sequence);
    }
  }
  info.points = n;
  return info;
}

}  // namespace trailnav::velodyne
