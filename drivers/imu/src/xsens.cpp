#include "trailnav/drivers/imu/xsens.hpp"
#include "trailnav/drivers/imu/stream_decoder.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <cstring>

namespace trailnav::imu {
namespace {

std::uint32_t be32(const std::uint8_t* p) noexcept {
  return static_cast<std::uint32_t>(p[0]) << 24 | static_cast<std::uint32_t>(p[1]) << 16 |
         static_cast<std::uint32_t>(p[2]) << 8 | p[3];
}
std::uint16_t be16(const std::uint8_t* p) noexcept { return static_cast<std::uint16_t>(p[0] << 8 | p[1]); }

// Bytes per number of each format: float32, fixed 12.20, fixed 16.32, float64.
constexpr std::size_t kFormatBytes[4] = {4, 4, 6, 8};

double read_number(const std::uint8_t* p, std::uint16_t format) noexcept {
  switch (format) {
    case 0: {
      const std::uint32_t v = be32(p);
      float f = 0.0f;
      std::memcpy(&f, &v, 4);
      return static_cast<double>(f);
    }
    case 1:  // signed 32-bit, 20 fractional bits
      return static_cast<double>(static_cast<std::int32_t>(be32(p))) / 1048576.0;
    case 2: {  // 32 fractional bits first, then the signed 16-bit integer part
      const std::uint64_t fraction = be32(p);
      const auto integer = static_cast<std::int16_t>(be16(p + 4));
      const std::int64_t fixed = static_cast<std::int64_t>(integer) * 4294967296LL + static_cast<std::int64_t>(fraction);
      return static_cast<double>(fixed) / 4294967296.0;
    }
    default: {
      const std::uint64_t v = static_cast<std::uint64_t>(be32(p)) << 32 | be32(p + 4);
      double d = 0.0;
      std::memcpy(&d, &v, 8);
      return d;
    }
  }
}

// The rotation taking vectors in the device's earth frame into ENU.
Eigen::Quaterniond earth_to_enu(std::uint16_t frame_bits) noexcept {
  const double h = std::sqrt(0.5);
  switch (frame_bits) {
    case 0x4: return {0.0, h, h, 0.0};  // NED: 180 degrees about (N+E)
    case 0x8: return {h, 0.0, 0.0, h};  // NWU: 90 degrees about up
    default: return Eigen::Quaterniond::Identity();
  }
}

template <std::size_t N>
bool read_vector(std::span<const std::uint8_t> value, std::uint16_t format, std::array<double, N>& out) noexcept {
  const std::size_t size = kFormatBytes[format];
  if (value.size() != N * size) return false;
  for (std::size_t i = 0; i < N; ++i) out[i] = read_number(value.data() + i * size, format);
  return true;
}

}  // namespace

XbusFramer::Scan XbusFramer::scan(std::size_t start, std::size_t& total) noexcept {
  const std::size_t available = length_ - start;
  if (available < 2) return Scan::need_more;
  // A single device always writes BID 0xFF: anything else is a 0xFA inside
  // other data, and waiting for its "length" would only delay the next message.
  if (buffer_[start + 1] != kXbusMaster) return Scan::drop;
  if (available < 4) return Scan::need_more;
  std::size_t header = 4;
  std::size_t payload = buffer_[start + 3];
  if (payload == 0xFF) {
    if (available < 6) return Scan::need_more;
    header = 6;
    payload = be16(&buffer_[start + 4]);
    if (payload > kXbusMaxPayload) {
      ++counters_.oversize;
      return Scan::drop;
    }
  }
  total = header + payload + 1;
  if (available < total) return Scan::need_more;
  std::uint8_t sum = 0;
  for (std::size_t i = start + 1; i < start + total; ++i) sum = static_cast<std::uint8_t>(sum + buffer_[i]);
  if (sum != 0) {
    ++counters_.bad_checksum;
    return Scan::drop;
  }
  return Scan::message;
}

std::size_t encode_xbus(std::uint8_t message_id, std::span<const std::uint8_t> payload, std::span<std::uint8_t> out,
                        std::uint8_t bid) noexcept {
  if (payload.size() > kXbusMaxPayload) return 0;
  const bool extended = payload.size() >= 0xFF;
  const std::size_t header = extended ? 6 : 4;
  const std::size_t total = header + payload.size() + 1;
  if (out.size() < total) return 0;
  out[0] = kXbusPreamble;
  out[1] = bid;
  out[2] = message_id;
  if (extended) {
    out[3] = 0xFF;
    out[4] = static_cast<std::uint8_t>(payload.size() >> 8);
    out[5] = static_cast<std::uint8_t>(payload.size());
  } else {
    out[3] = static_cast<std::uint8_t>(payload.size());
  }
  std::copy(payload.begin(), payload.end(), out.begin() + static_cast<std::ptrdiff_t>(header));
  std::uint8_t sum = 0;
  for (std::size_t i = 1; i < total - 1; ++i) sum = static_cast<std::uint8_t>(sum + out[i]);
  out[total - 1] = static_cast<std::uint8_t>(0x100 - sum);
  return total;
}

const char* xsens_error_name(XsensError e) noexcept {
  switch (e) {
    case XsensError::none: return "none";
    case XsensError::truncated_item: return "truncated_item";
    case XsensError::bad_item_size: return "bad_item_size";
    case XsensError::bad_frame: return "bad_frame";
    case XsensError::no_data: return "no_data";
  }
  return "unknown";
}

XsensError decode_mtdata2(std::span<const std::uint8_t> payload, ImuSample& s, MtData2Counters* counters) noexcept {
  std::uint32_t fields = 0;
  std::size_t o = 0;
  while (o < payload.size()) {
    if (payload.size() - o < 3) return XsensError::truncated_item;
    const std::uint16_t id = be16(&payload[o]);
    const std::size_t size = payload[o + 2];
    o += 3;
    if (payload.size() - o < size) return XsensError::truncated_item;
    const auto value = payload.subspan(o, size);
    o += size;
    if (counters) ++counters->items;
    const std::uint16_t type = id & xdi::kTypeMask;
    const std::uint16_t format = id & xdi::kFormatMask;
    const std::uint16_t frame = id & xdi::kFrameMask;
    bool ok = true;
    switch (type) {
      case xdi::kPacketCounter:
        ok = size == 2;
        if (ok) s.packet_counter = be16(value.data()), fields |= kPacketCounter;
        break;
      case xdi::kSampleTimeFine:
        ok = size == 4;
        if (ok) s.sample_time_fine = be32(value.data()), fields |= kSampleTimeFine;
        break;
      case xdi::kTemperature: {
        std::array<double, 1> t{};
        ok = read_vector(value, format, t);
        if (ok) s.temperature = t[0], fields |= kTemperature;
        break;
      }
      case xdi::kQuaternion: {
        if (frame == 0xC) return XsensError::bad_frame;
        std::array<double, 4> q{};
        ok = read_vector(value, format, q);
        if (ok) {
          const Eigen::Quaterniond e = earth_to_enu(frame) * Eigen::Quaterniond(q[0], q[1], q[2], q[3]);
          s.orientation = {e.w(), e.x(), e.y(), e.z()};
          fields |= kOrientation;
        }
        break;
      }
      case xdi::kEulerAngles: {
        if (frame == 0xC) return XsensError::bad_frame;
        std::array<double, 3> a{};
        ok = read_vector(value, format, a);
        if (ok) {
          constexpr double kDeg = M_PI / 180.0;
          const Eigen::Quaterniond q = Eigen::AngleAxisd(a[2] * kDeg, Eigen::Vector3d::UnitZ()) *
                                       Eigen::AngleAxisd(a[1] * kDeg, Eigen::Vector3d::UnitY()) *
                                       Eigen::AngleAxisd(a[0] * kDeg, Eigen::Vector3d::UnitX());
          const Eigen::Quaterniond e = earth_to_enu(frame) * q;
          // Quaternion output wins when the device sends both.
          if (!(fields & kOrientation)) s.orientation = {e.w(), e.x(), e.y(), e.z()};
          fields |= kOrientation;
        }
        break;
      }
      case xdi::kAcceleration:
        ok = read_vector(value, format, s.acceleration);
        if (ok) fields |= kAcceleration;
        break;
      case xdi::kFreeAcceleration: {
        if (frame == 0xC) return XsensError::bad_frame;
        ok = read_vector(value, format, s.free_acceleration);
        if (ok) {
          const Eigen::Vector3d v = earth_to_enu(frame) * Eigen::Vector3d(s.free_acceleration[0],
                                                                          s.free_acceleration[1],
                                                                          s.free_acceleration[2]);
          s.free_acceleration = {v.x(), v.y(), v.z()};
          fields |= kFreeAcceleration;
        }
        break;
      }
      case xdi::kRateOfTurn:
        ok = read_vector(value, format, s.rate_of_turn);
        if (ok) fields |= kRateOfTurn;
        break;
      case xdi::kMagneticField:
        ok = read_vector(value, format, s.magnetic_field);
        if (ok) fields |= kMagneticField;
        break;
      case xdi::kStatusWord:
        ok = size == 4;
        if (ok) s.status_word = be32(value.data()), fields |= kStatusWord;
        break;
      case xdi::kStatusByte:
        ok = size == 1;
        if (ok) s.status_word = value[0], fields |= kStatusWord;
        break;
      default:
        if (counters) ++counters->unused_items;
        break;
    }
    if (!ok) return XsensError::bad_item_size;
  }
  if (fields == 0) return XsensError::no_data;
  s.fields = fields;
  return XsensError::none;
}

const char* xsens_device_error_text(std::uint8_t code) noexcept {
  switch (code) {
    case 0x03: return "sample period out of range";
    case 0x04: return "invalid message";
    case 0x1E: return "timer overflow: the output rate is too high for the baud rate";
    case 0x20: return "requested baud rate out of range";
    case 0x21: return "invalid parameter in the request";
    case 0x28: return "device error";
    case 0x29: return "data overflow: the device's buffer is full";
    case 0x2A: return "buffer overflow: the sample frequency is too high";
  }
  return "unknown error code";
}

std::size_t encode_output_configuration(std::span<const OutputItem> items, std::span<std::uint8_t> out) noexcept {
  std::array<std::uint8_t, kXbusMaxPayload> payload{};
  if (items.size() * 4 > payload.size()) return 0;
  std::size_t o = 0;
  for (const OutputItem& item : items) {
    payload[o++] = static_cast<std::uint8_t>(item.id >> 8);
    payload[o++] = static_cast<std::uint8_t>(item.id);
    payload[o++] = static_cast<std::uint8_t>(item.rate_hz >> 8);
    payload[o++] = static_cast<std::uint8_t>(item.rate_hz);
  }
  return encode_xbus(mid::kSetOutputConfiguration, std::span<const std::uint8_t>(payload.data(), o), out);
}

const char* imu_protocol_name(ImuProtocol p) noexcept { return p == ImuProtocol::xsens ? "xsens" : "line"; }

}  // namespace trailnav::imu
