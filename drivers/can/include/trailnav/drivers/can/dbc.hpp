// CAN databases in the Vector DBC format: the subset real files use —
// messages (BO_) and their signals (SG_) with start bit, length, byte order,
// sign, factor, offset, range, unit and receivers. Everything else (comments,
// attributes, value tables, ...) is skipped. Multiplexed signals are kept but
// marked unsupported, so they are refused rather than misread.
//
// Parsing allocates (start-up); decode and encode do not.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace trailnav::can {

struct DbcSignal {
  std::string name;
  int start_bit = 0;          // as written in the file (Motorola: the most significant bit)
  int length = 1;             // bits, 1..64
  bool little_endian = true;  // @1 Intel, @0 Motorola
  bool is_signed = false;     // '-'
  double factor = 1.0;
  double offset = 0.0;
  double minimum = 0.0;
  double maximum = 0.0;
  std::string unit;
  std::vector<std::string> receivers;
  bool multiplexer = false;             // 'M': selects the multiplexed signals
  std::optional<int> multiplexed_by;    // 'm<k>': present when the multiplexer is k
  int line = 0;
};

struct DbcMessage {
  std::uint32_t id = 0;  // 11 or 29 bits, without the extended flag
  bool extended = false;
  std::string name;
  int size = 8;          // bytes
  std::string sender;
  std::vector<DbcSignal> signals;
  int line = 0;

  const DbcSignal* signal(std::string_view signal_name) const noexcept;
  bool multiplexed() const noexcept;
};

struct Dbc {
  std::string file;
  std::vector<DbcMessage> messages;
  // Problems that do not stop the file being used (file:line: what), e.g. a
  // signal that does not fit its message: decoding it reports short_frame.
  std::vector<std::string> warnings;

  const DbcMessage* message(std::uint32_t id, bool extended = false) const noexcept;
  const DbcMessage* message(std::string_view name) const noexcept;
};

struct DbcResult {
  std::optional<Dbc> dbc;
  std::string error;  // file:line: problem
};

DbcResult parse_dbc(std::string_view text, const std::string& file_name);
DbcResult load_dbc(const std::string& path);

enum class SignalError : std::uint8_t {
  none,
  short_frame,     // the frame has fewer bytes than the signal needs
  multiplexed,     // multiplexed signals are not supported
  out_of_range,    // encode: the value does not fit the signal
};
const char* signal_error_name(SignalError e) noexcept;

// Physical value of a signal in a frame's data: raw * factor + offset.
SignalError decode_signal(const DbcSignal& signal, std::span<const std::uint8_t> data, double& value) noexcept;
// Writes a physical value (rounded to the nearest raw step) into `data`.
SignalError encode_signal(const DbcSignal& signal, double value, std::span<std::uint8_t> data) noexcept;

}  // namespace trailnav::can
