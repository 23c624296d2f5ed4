#include "trailnav/drivers/can/dbc.hpp"

#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace trailnav::can {
namespace {

class ParseError {
 public:
  ParseError(int line, std::string what) : line_(line), what_(std::move(what)) {}
  int line() const { return line_; }
  const std::string& what() const { return what_; }

 private:
  int line_;
  std::string what_;
};

// A cursor over one statement.
struct Cursor {
  std::string_view s;
  std::size_t i = 0;
  int line = 0;

  void skip_space() {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t' || s[i] == '\r' || s[i] == '\n')) ++i;
  }
  bool at_end() {
    skip_space();
    return i >= s.size();
  }
  bool accept(char c) {
    skip_space();
    if (i < s.size() && s[i] == c) {
      ++i;
      return true;
    }
    return false;
  }
  void expect(char c, const char* what) {
    if (!accept(c)) throw ParseError(line, std::string("expected '") + c + "' " + what);
  }
  std::string_view identifier(const char* what) {
    skip_space();
    const std::size_t b = i;
    while (i < s.size() && (std::isalnum(static_cast<unsigned char>(s[i])) || s[i] == '_')) ++i;
    if (b == i) throw ParseError(line, std::string("expected ") + what);
    return s.substr(b, i - b);
  }
  double number(const char* what) {
    skip_space();
    const std::size_t b = i;
    while (i < s.size() && (std::isdigit(static_cast<unsigned char>(s[i])) || s[i] == '.' || s[i] == '-' || s[i] == '+' ||
                            s[i] == 'e' || s[i] == 'E')) {
      ++i;
    }
    const std::string text(s.substr(b, i - b));
    if (text.empty()) throw ParseError(line, std::string("expected a number for ") + what);
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(text.c_str(), &end);
    if (end != text.c_str() + text.size() || errno != 0 || !std::isfinite(v)) {
      throw ParseError(line, "'" + text + "' is not a number (" + what + ")");
    }
    return v;
  }
  long integer(const char* what) {
    const double v = number(what);
    if (v != std::floor(v) || std::abs(v) > 9.007e15) throw ParseError(line, std::string("expected an integer for ") + what);
    return static_cast<long>(v);
  }
  std::string quoted(const char* what) {
    skip_space();
    if (i >= s.size() || s[i] != '"') throw ParseError(line, std::string("expected a quoted ") + what);
    const std::size_t b = ++i;
    while (i < s.size() && s[i] != '"') ++i;
    if (i >= s.size()) throw ParseError(line, std::string("unterminated ") + what);
    return std::string(s.substr(b, i++ - b));
  }
};

// Bit positions of a signal, least significant first, as byte*8 + bit.
template <typename F>
bool for_each_bit(const DbcSignal& sig, int frame_bits, F&& f) {
  if (sig.little_endian) {
    for (int k = 0; k < sig.length; ++k) {
      const int pos = sig.start_bit + k;
      if (pos >= frame_bits) return false;
      f(k, pos);
    }
    return true;
  }
  // Motorola: start at the most significant bit and walk the "sawtooth".
  int pos = sig.start_bit;
  for (int k = sig.length - 1; k >= 0; --k) {
    if (pos < 0 || pos >= frame_bits) return false;
    f(k, pos);
    if (pos % 8 == 0) pos += 15;
    else --pos;
  }
  return true;
}

bool fits(const DbcSignal& sig, int frame_bits) {
  return for_each_bit(sig, frame_bits, [](int, int) {});
}

DbcSignal parse_signal(Cursor& c) {
  DbcSignal sig;
  sig.line = c.line;
  sig.name = std::string(c.identifier("a signal name after SG_"));
  c.skip_space();
  if (c.i < c.s.size() && c.s[c.i] != ':') {
    const std::string_view mux = c.identifier("a multiplexer indicator (M or m<k>) or ':'");
    if (mux == "M") {
      sig.multiplexer = true;
    } else if (mux.size() > 1 && mux[0] == 'm') {
      int k = 0;
      const auto r = std::from_chars(mux.data() + 1, mux.data() + mux.size(), k);
      if (r.ec != std::errc() || r.ptr != mux.data() + mux.size()) {
        // Extended multiplexing ("m3M") is refused too, as multiplexed.
        k = -1;
      }
      sig.multiplexed_by = k;
    } else {
      throw ParseError(c.line, "signal " + sig.name + ": '" + std::string(mux) + "' is not a multiplexer indicator");
    }
  }
  c.expect(':', ("after signal " + sig.name).c_str());
  sig.start_bit = static_cast<int>(c.integer("the start bit"));
  c.expect('|', "between start bit and length");
  sig.length = static_cast<int>(c.integer("the length"));
  c.expect('@', "before the byte order");
  c.skip_space();
  if (c.i >= c.s.size() || (c.s[c.i] != '0' && c.s[c.i] != '1')) {
    throw ParseError(c.line, "signal " + sig.name + ": byte order must be 0 (Motorola) or 1 (Intel)");
  }
  sig.little_endian = c.s[c.i++] == '1';
  if (c.i >= c.s.size() || (c.s[c.i] != '+' && c.s[c.i] != '-')) {
    throw ParseError(c.line, "signal " + sig.name + ": sign must be + (unsigned) or - (signed)");
  }
  sig.is_signed = c.s[c.i++] == '-';
  c.expect('(', "before factor,offset");
  sig.factor = c.number("the factor");
  c.expect(',', "between factor and offset");
  sig.offset = c.number("the offset");
  c.expect(')', "after factor,offset");
  c.expect('[', "before min|max");
  sig.minimum = c.number("the minimum");
  c.expect('|', "between minimum and maximum");
  sig.maximum = c.number("the maximum");
  c.expect(']', "after min|max");
  sig.unit = c.quoted("unit");
  while (!c.at_end()) {
    sig.receivers.emplace_back(c.identifier("a receiver node"));
    c.accept(',');
  }
  if (sig.length < 1 || sig.length > 64) throw ParseError(c.line, "signal " + sig.name + ": length must be 1..64 bits");
  if (sig.start_bit < 0 || sig.start_bit > 511) throw ParseError(c.line, "signal " + sig.name + ": start bit must be 0..511");
  if (sig.factor == 0.0) throw ParseError(c.line, "signal " + sig.name + ": factor must not be 0");
  return sig;
}

// Splits the text into statements: one per line, except that a quoted
// string may run over several lines (comments, attribute values).
std::vector<std::pair<int, std::string>> statements(std::string_view text) {
  std::vector<std::pair<int, std::string>> out;
  std::string current;
  int start_line = 0;
  int line = 0;
  bool in_quote = false;
  std::size_t pos = 0;
  while (pos <= text.size()) {
    const std::size_t end = std::min(text.find('\n', pos), text.size());
    const std::string_view l = text.substr(pos, end - pos);
    ++line;
    if (!in_quote) {
      current.clear();
      start_line = line;
    } else {
      current.push_back('\n');
    }
    for (std::size_t k = 0; k < l.size(); ++k) {
      if (l[k] == '"' && (k == 0 || l[k - 1] != '\\')) in_quote = !in_quote;
    }
    current.append(l);
    if (!in_quote) out.emplace_back(start_line, current);
    if (end == text.size()) break;
    pos = end + 1;
  }
  if (in_quote) out.emplace_back(start_line, current);  // reported by the statement's parser, or skipped
  return out;
}

}  // namespace

const DbcSignal* DbcMessage::signal(std::string_view signal_name) const noexcept {
  for (const DbcSignal& s : signals) {
    if (s.name == signal_name) return &s;
  }
  return nullptr;
}

bool DbcMessage::multiplexed() const noexcept {
  for (const DbcSignal& s : signals) {
    if (s.multiplexer || s.multiplexed_by) return true;
  }
  return false;
}

const DbcMessage* Dbc::message(std::uint32_t id, bool extended) const noexcept {
  for (const DbcMessage& m : messages) {
    if (m.id == id && m.extended == extended) return &m;
  }
  return nullptr;
}

const DbcMessage* Dbc::message(std::string_view name) const noexcept {
  for (const DbcMessage& m : messages) {
    if (m.name == name) return &m;
  }
  return nullptr;
}

DbcResult parse_dbc(std::string_view text, const std::string& file_name) {
  Dbc dbc;
  dbc.file = file_name;
  try {
    DbcMessage* current = nullptr;
    for (const auto& [line, statement] : statements(text)) {
      Cursor c{statement, 0, line};
      if (c.at_end()) continue;
      const std::size_t mark = c.i;
      std::string_view keyword;
      if (std::isalpha(static_cast<unsigned char>(statement[mark])) || statement[mark] == '_') {
        keyword = c.identifier("a keyword");
      }
      if (keyword == "BO_") {
        const long raw_id = c.integer("the message id");
        if (raw_id < 0 || raw_id > 0xFFFFFFFFL) throw ParseError(line, "message id out of range");
        DbcMessage m;
        m.line = line;
        m.extended = (raw_id & 0x80000000L) != 0;
        m.id = static_cast<std::uint32_t>(raw_id) & 0x1FFFFFFFu;
        if (!m.extended && m.id > 0x7FF) {
          throw ParseError(line, "standard message id " + std::to_string(m.id) + " exceeds 11 bits (extended ids carry bit 31)");
        }
        m.name = std::string(c.identifier("a message name"));
        c.expect(':', "after the message name");
        const long size = c.integer("the message size");
        if (size < 0 || size > 64) throw ParseError(line, "message " + m.name + ": size must be 0..64 bytes");
        m.size = static_cast<int>(size);
        if (!c.at_end()) m.sender = std::string(c.identifier("the sending node"));
        if (dbc.message(m.id, m.extended)) {
          throw ParseError(line, "message id " + std::to_string(m.id) + " (" + m.name + ") is defined twice");
        }
        dbc.messages.push_back(std::move(m));
        current = &dbc.messages.back();
      } else if (keyword == "SG_") {
        if (!current) throw ParseError(line, "SG_ outside a message (no BO_ before it)");
        DbcSignal sig = parse_signal(c);
        if (!fits(sig, current->size * 8)) {
          // Real databases carry such slips; keep the rest of the file usable.
          dbc.warnings.push_back(file_name + ":" + std::to_string(line) + ": signal " + sig.name + " (start " +
                                 std::to_string(sig.start_bit) + ", " + std::to_string(sig.length) +
                                 " bits) does not fit message " + current->name + " of " + std::to_string(current->size) +
                                 " bytes; it is kept but never decoded");
        }
        if (current->signal(sig.name)) throw ParseError(line, "signal " + sig.name + " is defined twice in " + current->name);
        current->signals.push_back(std::move(sig));
      } else {
        // Any other statement ends the message's signal list.
        if (!keyword.empty()) current = nullptr;
      }
    }
  } catch (const ParseError& e) {
    return {std::nullopt, file_name + ":" + std::to_string(e.line()) + ": " + e.what()};
  }
  return {std::move(dbc), ""};
}

DbcResult load_dbc(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {std::nullopt, path + ": cannot open"};
  std::stringstream buffer;
  buffer << in.rdbuf();
  return parse_dbc(buffer.str(), path);
}

const char* signal_error_name(SignalError e) noexcept {
  switch (e) {
    case SignalError::none: return "none";
    case SignalError::short_frame: return "short_frame";
    case SignalError::multiplexed: return "multiplexed";
    case SignalError::out_of_range: return "out_of_range";
  }
  return "?";
}

SignalError decode_signal(const DbcSignal& sig, std::span<const std::uint8_t> data, double& value) noexcept {
  if (sig.multiplexer || sig.multiplexed_by) return SignalError::multiplexed;
  std::uint64_t raw = 0;
  const bool ok = for_each_bit(sig, static_cast<int>(data.size() * 8), [&](int k, int pos) {
    const unsigned byte = data[static_cast<std::size_t>(pos / 8)];
    const std::uint64_t bit = (byte >> static_cast<unsigned>(pos % 8)) & 1u;
    raw |= bit << k;
  });
  if (!ok) return SignalError::short_frame;
  double r = 0.0;
  if (sig.is_signed && sig.length < 64 && (raw >> (sig.length - 1)) & 1u) {
    r = static_cast<double>(static_cast<std::int64_t>(raw | (~std::uint64_t{0} << sig.length)));
  } else if (sig.is_signed) {
    r = static_cast<double>(static_cast<std::int64_t>(raw));
  } else {
    r = static_cast<double>(raw);
  }
  value = r * sig.factor + sig.offset;
  return SignalError::none;
}

SignalError encode_signal(const DbcSignal& sig, double value, std::span<std::uint8_t> data) noexcept {
  if (sig.multiplexer || sig.multiplexed_by) return SignalError::multiplexed;
  if (!fits(sig, static_cast<int>(data.size() * 8))) return SignalError::short_frame;
  const double r = std::nearbyint((value - sig.offset) / sig.factor);
  const double lo = sig.is_signed ? -std::ldexp(1.0, sig.length - 1) : 0.0;
  const double hi = sig.is_signed ? std::ldexp(1.0, sig.length - 1) - 1.0 : std::ldexp(1.0, sig.length) - 1.0;
  if (!(r >= lo && r <= hi)) return SignalError::out_of_range;
  const auto raw = sig.is_signed ? static_cast<std::uint64_t>(static_cast<std::int64_t>(r)) : static_cast<std::uint64_t>(r);
  for_each_bit(sig, static_cast<int>(data.size() * 8), [&](int k, int pos) {
    auto& byte = data[static_cast<std::size_t>(pos / 8)];
    const auto mask = static_cast<std::uint8_t>(1u << (pos % 8));
    if ((raw >> k) & 1u) byte = static_cast<std::uint8_t>(byte | mask);
    else byte = static_cast<std::uint8_t>(byte & ~mask);
  });
  return SignalError::none;
}

}  // namespace trailnav::can
