#include "trailnav/drivers/cloud/cloud_file.hpp"

#include <lzf.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <optional>

namespace trailnav::cloud {

PointCloud::PointCloud(std::size_t capacity)
    : x(capacity), y(capacity), z(capacity), intensity(capacity), ring(capacity), time(capacity) {}

double first_time(const PointCloud& c) noexcept {
  if (!c.has_time) return 0.0;
  double t0 = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < c.size; ++i) t0 = std::isfinite(c.time[i]) ? std::min(t0, c.time[i]) : t0;
  return std::isfinite(t0) ? t0 : 0.0;
}

namespace {

enum class Role : std::uint8_t { none, x, y, z, intensity, ring, time };
enum class Scalar : std::uint8_t { i8, u8, i16, u16, i32, u32, f32, f64 };

std::size_t scalar_size(Scalar s) noexcept {
  switch (s) {
    case Scalar::i8:
    case Scalar::u8: return 1;
    case Scalar::i16:
    case Scalar::u16: return 2;
    case Scalar::i32:
    case Scalar::u32:
    case Scalar::f32: return 4;
    case Scalar::f64: return 8;
  }
  return 0;
}

// Case-insensitive equality (no allocation).
bool same(std::string_view a, std::string_view b) noexcept {
  if (a.size() != b.size()) return false;
  for (std::size_t k = 0; k < a.size(); ++k) {
    if (std::tolower(static_cast<unsigned char>(a[k])) != std::tolower(static_cast<unsigned char>(b[k]))) return false;
  }
  return true;
}
bool any_of(std::string_view n, std::initializer_list<std::string_view> names) noexcept {
  for (std::string_view m : names) {
    if (same(n, m)) return true;
  }
  return false;
}

Role role_of(std::string_view n) noexcept {
  if (same(n, "x")) return Role::x;
  if (same(n, "y")) return Role::y;
  if (same(n, "z")) return Role::z;
  if (any_of(n, {"intensity", "reflectance", "reflectivity", "remission", "i"})) return Role::intensity;
  if (any_of(n, {"ring", "laser_id", "channel", "line"})) return Role::ring;
  if (any_of(n, {"time", "t", "timestamp", "offset_time"})) return Role::time;
  return Role::none;
}

// One field of a point record.
struct Field {
  Role role = Role::none;
  Scalar type = Scalar::f32;
  std::size_t count = 1;       // elements (PCD COUNT); the first is taken
  std::size_t offset = 0;      // bytes into a binary record
  std::size_t bytes = 0;       // of all its elements in a binary record (PCD: SIZE x COUNT)
  bool list = false;           // PLY list property: a count of `count_type`, then that many `type`
  bool padding = false;        // PCD field "_": PCL writes it in binary records, leaves it out of compressed data
  Scalar count_type = Scalar::u8;
};

// One value of `T` from its bytes (already in the host's order).
template <typename T>
double as(const std::array<std::uint8_t, 8>& b) noexcept {
  T v;
  std::memcpy(&v, b.data(), sizeof v);
  return static_cast<double>(v);
}

double read_scalar(const std::uint8_t* p, Scalar s, bool big_endian) noexcept {
  std::array<std::uint8_t, 8> b{};
  const std::size_t n = scalar_size(s);
  for (std::size_t k = 0; k < n; ++k) b[k] = big_endian ? p[n - 1 - k] : p[k];
  switch (s) {
    case Scalar::i8: return as<std::int8_t>(b);
    case Scalar::u8: return as<std::uint8_t>(b);
    case Scalar::i16: return as<std::int16_t>(b);
    case Scalar::u16: return as<std::uint16_t>(b);
    case Scalar::i32: return as<std::int32_t>(b);
    case Scalar::u32: return as<std::uint32_t>(b);
    case Scalar::f32: return as<float>(b);
    case Scalar::f64: return as<double>(b);
  }
  return 0.0;
}

void ensure(PointCloud& c, std::size_t n) {
  if (c.capacity() >= n) return;
  for (auto* v : {&c.x, &c.y, &c.z, &c.intensity}) v->resize(n);
  c.ring.resize(n);
  c.time.resize(n);
}

template <typename List>
void begin_cloud(PointCloud& c, std::size_t n, const List& fields) {
  ensure(c, n);
  c.size = n;
  c.has_intensity = c.has_ring = c.has_time = false;
  for (const Field& f : fields) {
    c.has_intensity = c.has_intensity || f.role == Role::intensity;
    c.has_ring = c.has_ring || f.role == Role::ring;
    c.has_time = c.has_time || f.role == Role::time;
  }
  if (!c.has_intensity) std::fill(c.intensity.begin(), c.intensity.begin() + static_cast<std::ptrdiff_t>(n), 0.0f);
}

// A time field's unit: seconds in a floating-point field, nanoseconds in an
// integer one (Ouster's `t` and Livox's `offset_time`: uint32 ns after the
// scan's start; Velodyne's and Hesai's drivers write float seconds).
double time_scale(Scalar s) noexcept { return s == Scalar::f32 || s == Scalar::f64 ? 1.0 : 1e-9; }

// Stores one value of field `f`; an error text for a ring that is no laser index.
const char* store(PointCloud& c, std::size_t i, const Field& f, double v) noexcept {
  switch (f.role) {
    case Role::none: break;
    case Role::x: c.x[i] = static_cast<float>(v); break;
    case Role::y: c.y[i] = static_cast<float>(v); break;
    case Role::z: c.z[i] = static_cast<float>(v); break;
    case Role::intensity: c.intensity[i] = static_cast<float>(v); break;
    case Role::ring:
      if (!(v >= 0.0 && v <= 65535.0) || std::floor(v) != v) return "a ring that is not a whole number from 0 to 65535";
      c.ring[i] = static_cast<std::uint16_t>(v);
      break;
    case Role::time: c.time[i] = v * time_scale(f.type); break;
  }
  return nullptr;
}

Status fail(const std::string& name, const std::string& what) { return Status::error(name + ": " + what); }

template <typename List>
std::string missing_xyz(const List& fields) {
  bool x = false, y = false, z = false;
  for (const Field& f : fields) {
    x = x || f.role == Role::x;
    y = y || f.role == Role::y;
    z = z || f.role == Role::z;
  }
  if (x && y && z) return {};
  return "no field x, y and z: a point cloud needs the points' coordinates";
}

// A header line's words (spaces and tabs), at most kMaxWords.
constexpr std::size_t kMaxFields = 64;
constexpr std::size_t kMaxWords = kMaxFields + 1;
struct Words {
  std::array<std::string_view, kMaxWords> w{};
  std::size_t n = 0;
  bool overflow = false;
  std::size_t size() const noexcept { return n; }
  bool empty() const noexcept { return n == 0; }
  std::string_view operator[](std::size_t k) const noexcept { return w[k]; }
};
// A file's header, a line at a time; `pos` is then where the data begin.
struct HeaderLines {
  std::span<const std::uint8_t> bytes;
  std::size_t pos = 0;
  int number = 0;  // of the line last read, from 1
  bool next(std::string_view& line) noexcept {
    if (pos >= bytes.size()) return false;
    std::size_t eol = pos;
    while (eol < bytes.size() && bytes[eol] != '\n') ++eol;
    line = std::string_view(reinterpret_cast<const char*>(bytes.data()) + pos, eol - pos);
    pos = std::min(eol + 1, bytes.size());
    ++number;
    return true;
  }
};

Words words(std::string_view line) noexcept {
  Words out;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    std::size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r') ++j;
    if (j > i) {
      if (out.n == kMaxWords) {
        out.overflow = true;
        break;
      }
      out.w[out.n++] = line.substr(i, j - i);
    }
    i = j;
  }
  return out;
}

// A fixed-capacity list of fields (no allocation).
struct Fields {
  std::array<Field, kMaxFields> f{};
  std::size_t n = 0;
  std::size_t size() const noexcept { return n; }
  bool empty() const noexcept { return n == 0; }
  Field& operator[](std::size_t k) noexcept { return f[k]; }
  const Field& operator[](std::size_t k) const noexcept { return f[k]; }
  const Field* begin() const noexcept { return f.data(); }
  const Field* end() const noexcept { return f.data() + n; }
  bool push(const Field& x) noexcept {
    if (n == kMaxFields) return false;
    f[n++] = x;
    return true;
  }
};

bool parse_size(std::string_view s, std::size_t& out) {
  const auto r = std::from_chars(s.data(), s.data() + s.size(), out);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

// ASCII values, one point a line, `per_point` numbers.
class AsciiPoints {
 public:
  explicit AsciiPoints(std::span<const std::uint8_t> d)
      : p_(reinterpret_cast<const char*>(d.data())), end_(p_ + d.size()) {}
  // The next number on the current line; false at the line's end.
  bool next(double& v) {
    while (p_ < end_ && (*p_ == ' ' || *p_ == '\t' || *p_ == '\r')) ++p_;
    if (p_ == end_ || *p_ == '\n') return false;
    const char* s = p_;
    while (p_ < end_ && *p_ != ' ' && *p_ != '\t' && *p_ != '\r' && *p_ != '\n') ++p_;
    const auto r = std::from_chars(s, p_, v);
    if (r.ec == std::errc::result_out_of_range) {
      v = std::numeric_limits<double>::infinity();
      return true;
    }
    if (r.ec != std::errc() || r.ptr != p_) {
      // "nan" and "inf" as PCL writes them.
      const std::string_view t(s, static_cast<std::size_t>(p_ - s));
      if (same(t, "nan") || same(t, "-nan")) {
        v = std::nan("");
        return true;
      }
      bad_ = true;
      return false;
    }
    return true;
  }
  // Past the rest of the line; false at the end of the data.
  bool next_line() {
    while (p_ < end_ && *p_ != '\n') ++p_;
    if (p_ == end_) return false;
    ++p_;
    return true;
  }
  bool at_end() {
    while (p_ < end_ && (*p_ == ' ' || *p_ == '\t' || *p_ == '\r' || *p_ == '\n')) ++p_;
    return p_ == end_;
  }
  bool bad() const noexcept { return bad_; }

 private:
  const char* p_;
  const char* end_;
  bool bad_ = false;
};

// --- KITTI ---

Status read_kitti(std::span<const std::uint8_t> b, const std::string& name, PointCloud& out) {
  if (b.size() % 16 != 0) {
    return fail(name, std::to_string(b.size()) + " bytes: not a KITTI scan (16 bytes a point: float32 x, y, z, reflectance)");
  }
  const std::size_t n = b.size() / 16;
  if (n > kMaxPoints) return fail(name, std::to_string(n) + " points; a cloud holds at most " + std::to_string(kMaxPoints));
  const std::array<Field, 4> fields{{{Role::x}, {Role::y}, {Role::z}, {Role::intensity}}};
  begin_cloud(out, n, fields);
  for (std::size_t i = 0; i < n; ++i) {
    float v[4];
    std::memcpy(v, b.data() + 16 * i, 16);
    out.x[i] = v[0];
    out.y[i] = v[1];
    out.z[i] = v[2];
    out.intensity[i] = v[3];
  }
  return Status::ok();
}

// --- PCD ---

Status read_pcd(std::span<const std::uint8_t> b, const std::string& name, PointCloud& out, CloudScratch& scratch) {
  Fields fields;
  std::array<std::size_t, kMaxFields> sizes{};
  std::array<char, kMaxFields> types{};
  std::size_t n_sizes = 0, n_types = 0;
  bool seen_size = false, seen_count = false;
  std::size_t width = 0, height = 1, points = 0;
  bool have_points = false, have_width = false;
  std::string_view data;
  HeaderLines lines{b};
  std::string_view line;
  // Errors only build their text.
  auto at = [&](const std::string& what) { return fail(name, "header line " + std::to_string(lines.number) + ": " + what); };
  while (lines.next(line)) {
    const Words w = words(line);
    if (w.overflow) return at("more than " + std::to_string(kMaxFields) + " fields");
    if (w.empty() || w[0][0] == '#') continue;
    const std::string_view key = w[0];
    if (same(key, "version") || same(key, "viewpoint")) continue;
    if (same(key, "fields")) {
      if (!fields.empty()) return at("FIELDS given twice");
      for (std::size_t k = 1; k < w.size(); ++k) {
        Field f{role_of(w[k])};
        f.padding = w[k] == "_";
        fields.push(f);
      }
      continue;
    }
    if (same(key, "size") || same(key, "count")) {
      bool& seen = same(key, "size") ? seen_size : seen_count;
      if (seen) return at(std::string(key) + " given twice");
      seen = true;
      if (w.size() - 1 != fields.size()) {
        return at(std::string(key) + " gives " + std::to_string(w.size() - 1) + " values for " +
                  std::to_string(fields.size()) + " fields");
      }
      for (std::size_t k = 1; k < w.size(); ++k) {
        std::size_t v = 0;
        if (!parse_size(w[k], v) || v == 0) return at(std::string(key) + " '" + std::string(w[k]) + "' is not a positive number");
        if (same(key, "size")) {
          sizes[n_sizes++] = v;
        } else {
          fields[k - 1].count = v;
        }
      }
      continue;
    }
    if (same(key, "type")) {
      if (n_types > 0) return at("TYPE given twice");
      if (w.size() - 1 != fields.size()) {
        return at("TYPE gives " + std::to_string(w.size() - 1) + " values for " + std::to_string(fields.size()) + " fields");
      }
      for (std::size_t k = 1; k < w.size(); ++k) types[n_types++] = static_cast<char>(std::toupper(static_cast<unsigned char>(w[k][0])));
      continue;
    }
    if (same(key, "width") || same(key, "height") || same(key, "points")) {
      std::size_t v = 0;
      if (w.size() != 2 || !parse_size(w[1], v)) return at(std::string(key) + " needs one whole number");
      if (same(key, "width")) {
        width = v;
        have_width = true;
      } else if (same(key, "height")) {
        height = v;
      } else {
        points = v;
        have_points = true;
      }
      continue;
    }
    if (same(key, "data")) {
      if (w.size() != 2) return at("DATA needs one of ascii, binary, binary_compressed");
      data = w[1];
      break;
    }
    return at("unknown header key '" + std::string(w[0]) + "'");
  }
  if (data.empty()) return fail(name, "no DATA line: not a PCD file, or its header is cut short");
  if (fields.empty()) return fail(name, "no FIELDS line");
  if (n_sizes != fields.size() || n_types != fields.size()) {
    return fail(name, "FIELDS, SIZE and TYPE must give one value per field");
  }
  if (!have_points) {
    if (!have_width) return fail(name, "neither POINTS nor WIDTH: how many points is not said");
    points = width * height;
  }
  if (have_width && width * height != points) {
    return fail(name, "WIDTH x HEIGHT (" + std::to_string(width) + " x " + std::to_string(height) + ") is not POINTS (" +
                          std::to_string(points) + ")");
  }
  std::size_t record = 0;
  for (std::size_t k = 0; k < fields.size(); ++k) {
    Field& f = fields[k];
    const char t = types[k];
    const std::size_t s = sizes[k];
    if (t == 'F' && s == 4) f.type = Scalar::f32;
    else if (t == 'F' && s == 8) f.type = Scalar::f64;
    else if (t == 'I' && s == 1) f.type = Scalar::i8;
    else if (t == 'I' && s == 2) f.type = Scalar::i16;
    else if (t == 'I' && s == 4) f.type = Scalar::i32;
    else if (t == 'U' && s == 1) f.type = Scalar::u8;
    else if (t == 'U' && s == 2) f.type = Scalar::u16;
    else if (t == 'U' && s == 4) f.type = Scalar::u32;
    else if (f.role != Role::none) {
      return fail(name, "field " + std::to_string(k + 1) + ": TYPE " + std::string(1, t) + " of SIZE " + std::to_string(s) +
                            " is not a number this reader knows (I, U: 1, 2, 4; F: 4, 8)");
    }
    f.offset = record;
    f.bytes = s * f.count;
    record += f.bytes;
  }
  if (const std::string e = missing_xyz(fields); !e.empty()) return fail(name, e);
  if (points > kMaxPoints) return fail(name, std::to_string(points) + " points; a cloud holds at most " + std::to_string(kMaxPoints));
  const std::span<const std::uint8_t> body = b.subspan(lines.pos);
  begin_cloud(out, points, fields);
  if (same(data, "ascii")) {
    AsciiPoints a(body);
    for (std::size_t i = 0; i < points; ++i) {
      for (const Field& f : fields) {
        for (std::size_t e = 0; e < f.count; ++e) {
          double v = 0.0;
          if (!a.next(v)) {
            return fail(name, "point " + std::to_string(i + 1) + ": " +
                                  (a.bad() ? "a value that is not a number" : "fewer values than the fields need"));
          }
          if (e == 0) {
            if (const char* why = store(out, i, f, v)) return fail(name, "point " + std::to_string(i + 1) + ": " + why);
          }
        }
      }
      const bool more = a.next_line();
      if (!more && i + 1 < points) {
        return fail(name, "the data ends after " + std::to_string(i + 1) + " of " + std::to_string(points) + " points");
      }
    }
    return Status::ok();
  }
  const std::uint8_t* base = nullptr;
  bool columns = false;  // binary_compressed: each field's values one after another
  if (same(data, "binary")) {
    if (body.size() < points * record) {
      return fail(name, "the data holds " + std::to_string(body.size()) + " bytes; " + std::to_string(points) + " points of " +
                            std::to_string(record) + " bytes need " + std::to_string(points * record));
    }
    base = body.data();
  } else if (same(data, "binary_compressed")) {
    if (body.size() < 8) return fail(name, "binary_compressed data without its two sizes");
    std::uint32_t packed = 0, unpacked = 0;
    std::memcpy(&packed, body.data(), 4);
    std::memcpy(&unpacked, body.data() + 4, 4);
    // PCL leaves padding fields ("_") out of compressed data.
    std::size_t packed_record = 0;
    for (const Field& f : fields) packed_record += f.padding ? 0 : f.bytes;
    if (unpacked != points * packed_record) {
      return fail(name, "binary_compressed data of " + std::to_string(unpacked) + " bytes; " + std::to_string(points) +
                            " points of " + std::to_string(packed_record) + " bytes are " +
                            std::to_string(points * packed_record));
    }
    if (body.size() - 8 < packed) return fail(name, "binary_compressed data cut short (" + std::to_string(packed) + " bytes said)");
    if (scratch.inflated.size() < unpacked) scratch.inflated.resize(unpacked);
    if (unpacked > 0) {
      const unsigned got = lzf_decompress(body.data() + 8, packed, scratch.inflated.data(), unpacked);
      if (got != unpacked) return fail(name, "binary_compressed data does not inflate to the size it gives (corrupt)");
    }
    base = scratch.inflated.data();
    columns = true;
  } else {
    return fail(name, "DATA '" + std::string(data) + "': one of ascii, binary, binary_compressed");
  }
  std::size_t column_start = 0;
  for (const Field& f : fields) {
    if (columns && f.padding) continue;
    const std::size_t fsize = f.bytes;  // the file's SIZE x COUNT, whatever the type (a field not read may be any)
    if (f.role != Role::none) {
      for (std::size_t i = 0; i < points; ++i) {
        const std::uint8_t* p = columns ? base + column_start * points + i * fsize : base + i * record + f.offset;
        if (const char* why = store(out, i, f, read_scalar(p, f.type, false))) {
          return fail(name, "point " + std::to_string(i + 1) + ": " + why);
        }
      }
    }
    column_start += columns ? fsize : 0;
  }
  return Status::ok();
}

// --- PLY ---

std::optional<Scalar> ply_type(std::string_view t) noexcept {
  if (same(t, "char") || same(t, "int8")) return Scalar::i8;
  if (same(t, "uchar") || same(t, "uint8")) return Scalar::u8;
  if (same(t, "short") || same(t, "int16")) return Scalar::i16;
  if (same(t, "ushort") || same(t, "uint16")) return Scalar::u16;
  if (same(t, "int") || same(t, "int32")) return Scalar::i32;
  if (same(t, "uint") || same(t, "uint32")) return Scalar::u32;
  if (same(t, "float") || same(t, "float32")) return Scalar::f32;
  if (same(t, "double") || same(t, "float64")) return Scalar::f64;
  return std::nullopt;
}

struct PlyElement {
  std::string_view name;  // into the file's bytes
  std::size_t count = 0;
  Fields properties;
};
constexpr std::size_t kMaxElements = 8;

Status read_ply(std::span<const std::uint8_t> b, const std::string& name, PointCloud& out) {
  std::array<PlyElement, kMaxElements> elements_store{};
  std::size_t n_elements = 0;
  std::string_view format;
  HeaderLines lines{b};
  std::string_view line;
  bool ended = false;
  auto header_error = [&](const std::string& what) {
    return fail(name, "header line " + std::to_string(lines.number) + ": " + what);
  };
  while (lines.next(line)) {
    const Words w = words(line);
    if (lines.number == 1) {
      if (w.size() != 1 || w[0] != "ply") return fail(name, "not a PLY file (its first line is not 'ply')");
      continue;
    }
    if (w.empty()) continue;
    if (w[0] == "comment" || w[0] == "obj_info") continue;
    if (w.overflow) return header_error("more words than a PLY header line has");
    if (w[0] == "format") {
      if (w.size() != 3) return header_error("format needs its kind and version");
      format = w[1];
      if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian") {
        return header_error("format '" + std::string(format) + "': ascii, binary_little_endian or binary_big_endian");
      }
      continue;
    }
    if (w[0] == "element") {
      std::size_t n = 0;
      if (w.size() != 3 || !parse_size(w[2], n)) return header_error("element needs a name and a count");
      if (n_elements == kMaxElements) return header_error("more than " + std::to_string(kMaxElements) + " elements");
      elements_store[n_elements].name = w[1];
      elements_store[n_elements].count = n;
      ++n_elements;
      continue;
    }
    if (w[0] == "property") {
      if (n_elements == 0) return header_error("a property before any element");
      PlyElement& e = elements_store[n_elements - 1];
      Field f;
      if (w.size() == 5 && w[1] == "list") {
        const auto ct = ply_type(w[2]);
        const auto vt = ply_type(w[3]);
        if (!ct || !vt) return header_error("unknown type in '" + std::string(line) + "'");
        f.list = true;
        f.count_type = *ct;
        f.type = *vt;
      } else if (w.size() == 3) {
        const auto t = ply_type(w[1]);
        if (!t) return header_error("unknown type '" + std::string(w[1]) + "'");
        f.type = *t;
        f.role = e.name == "vertex" ? role_of(w[2]) : Role::none;
      } else {
        return header_error("property needs a type and a name");
      }
      if (!e.properties.push(f)) return header_error("more than " + std::to_string(kMaxFields) + " properties");
      continue;
    }
    if (w[0] == "end_header") {
      ended = true;
      break;
    }
    return header_error("unknown header keyword '" + std::string(w[0]) + "'");
  }
  const std::span<const PlyElement> elements(elements_store.data(), n_elements);
  if (!ended) return fail(name, "no end_header: the header is cut short");
  if (format.empty()) return fail(name, "no format line");
  const PlyElement* vertex = nullptr;
  for (const PlyElement& e : elements) {
    if (e.name == "vertex") vertex = &e;
  }
  if (vertex == nullptr) return fail(name, "no vertex element: no points");
  if (const std::string e = missing_xyz(vertex->properties); !e.empty()) return fail(name, "vertex: " + e);
  if (vertex->count > kMaxPoints) {
    return fail(name, std::to_string(vertex->count) + " vertices; a cloud holds at most " + std::to_string(kMaxPoints));
  }
  const std::span<const std::uint8_t> body = b.subspan(lines.pos);
  begin_cloud(out, vertex->count, vertex->properties);
  if (format == "ascii") {
    AsciiPoints a(body);
    for (const PlyElement& e : elements) {
      for (std::size_t i = 0; i < e.count; ++i) {
        auto where = [&](const char* what) {
          return fail(name, std::string(e.name) + " " + std::to_string(i + 1) + ": " + what);
        };
        for (const Field& f : e.properties) {
          double v = 0.0;
          if (!a.next(v)) return where(a.bad() ? "a value that is not a number" : "fewer values than its properties");
          if (f.list) {
            if (!(v >= 0.0) || std::floor(v) != v) return where("a list count that is not a count");
            for (double k = 0; k < v; ++k) {
              double item = 0.0;
              if (!a.next(item)) return where("a list shorter than its count");
            }
          } else if (&e == vertex) {
            if (const char* why = store(out, i, f, v)) return where(why);
          }
        }
        if (!a.next_line() && !(&e == &elements.back() && i + 1 == e.count)) {
          return fail(name, "the data ends in " + std::string(e.name) + " " + std::to_string(i + 1) + " of " +
                                std::to_string(e.count));
        }
      }
    }
    return Status::ok();
  }
  const bool big = format == "binary_big_endian";
  std::size_t at = 0;
  for (const PlyElement& e : elements) {
    // An element without properties holds no bytes, however many it counts
    // (billions of them walked one by one were the fuzzer's timeout).
    if (e.properties.empty()) continue;
    for (std::size_t i = 0; i < e.count; ++i) {
      for (const Field& f : e.properties) {
        if (f.list) {
          const std::size_t cs = scalar_size(f.count_type);
          if (body.size() - at < cs) return fail(name, "the data ends in " + std::string(e.name) + " " + std::to_string(i + 1));
          const double n = read_scalar(body.data() + at, f.count_type, big);
          at += cs;
          if (!(n >= 0.0)) return fail(name, std::string(e.name) + " " + std::to_string(i + 1) + ": a negative list count");
          const std::size_t skip = static_cast<std::size_t>(n) * scalar_size(f.type);
          if (body.size() - at < skip) return fail(name, "the data ends in " + std::string(e.name) + " " + std::to_string(i + 1));
          at += skip;
          continue;
        }
        const std::size_t s = scalar_size(f.type);
        if (body.size() - at < s) {
          return fail(name, "the data ends in " + std::string(e.name) + " " + std::to_string(i + 1) + " of " +
                                std::to_string(e.count));
        }
        if (&e == vertex && f.role != Role::none) {
          if (const char* why = store(out, i, f, read_scalar(body.data() + at, f.type, big))) {
            return fail(name, std::string(e.name) + " " + std::to_string(i + 1) + ": " + why);
          }
        }
        at += s;
      }
    }
  }
  return Status::ok();
}

}  // namespace

// --- sensor_msgs/PointCloud2 ---

namespace {

std::optional<Scalar> ros_type(std::uint8_t datatype) noexcept {
  switch (datatype) {
    case 1: return Scalar::i8;
    case 2: return Scalar::u8;
    case 3: return Scalar::i16;
    case 4: return Scalar::u16;
    case 5: return Scalar::i32;
    case 6: return Scalar::u32;
    case 7: return Scalar::f32;
    case 8: return Scalar::f64;
    default: return std::nullopt;
  }
}

// One field's first element of every point into the cloud, its type's
// load chosen once, not per point (read_scalar's switch and byte loop per
// value: the KITTI scan as a message in 3.76 ms instead of 1.14,
// BM_ReadPointCloud2, both in one session).
template <typename T>
const char* copy_field(const PointCloud2View& m, const Field& f, PointCloud& out, std::size_t& at) noexcept {
  const bool swap = m.is_bigendian != (std::endian::native == std::endian::big);
  std::size_t i = 0;
  for (std::uint32_t r = 0; r < m.height; ++r) {
    const std::uint8_t* row = m.data.data() + static_cast<std::size_t>(r) * m.row_step + f.offset;
    for (std::uint32_t c = 0; c < m.width; ++c, ++i) {
      std::array<std::uint8_t, sizeof(T)> b;
      std::memcpy(b.data(), row + static_cast<std::size_t>(c) * m.point_step, sizeof(T));
      if (swap) std::reverse(b.begin(), b.end());
      T v;
      std::memcpy(&v, b.data(), sizeof(T));
      if (const char* why = store(out, i, f, static_cast<double>(v))) {
        at = i;
        return why;
      }
    }
  }
  return nullptr;
}

}  // namespace

Status read_pointcloud2(const PointCloud2View& m, const std::string& name, PointCloud& out) {
  out.size = 0;
  const std::uint64_t points = static_cast<std::uint64_t>(m.height) * m.width;
  if (points > kMaxPoints) {
    return fail(name, std::to_string(m.height) + " x " + std::to_string(m.width) + " points; a cloud holds at most " +
                          std::to_string(kMaxPoints));
  }
  // One field a role (the last of a name given twice); the rest are skipped.
  std::array<Field, 7> roles{};
  for (const PointFieldView& v : m.fields) {
    const Role role = role_of(v.name);
    if (role == Role::none) continue;
    const auto what = [&v] { return "field '" + std::string(v.name) + "'"; };  // (built for an error only)
    const auto type = ros_type(v.datatype);
    if (!type) {
      return fail(name, what() + ": datatype " + std::to_string(v.datatype) +
                            " is not one of PointField's (1 INT8, 2 UINT8, 3 INT16, 4 UINT16, 5 INT32, 6 UINT32, 7 FLOAT32, "
                            "8 FLOAT64)");
    }
    if (v.count == 0) return fail(name, what() + ": count 0 (a field holds at least one value)");
    const std::uint64_t end = static_cast<std::uint64_t>(v.offset) + scalar_size(*type);
    if (end > m.point_step) {
      return fail(name, what() + " at offset " + std::to_string(v.offset) + " (" + std::to_string(scalar_size(*type)) +
                            " bytes) reaches past the point's " + std::to_string(m.point_step) + " bytes (point_step)");
    }
    Field& f = roles[static_cast<std::size_t>(role)];
    f.role = role;
    f.type = *type;
    f.offset = v.offset;
    f.bytes = scalar_size(*type);
  }
  if (const std::string e = missing_xyz(roles); !e.empty()) return fail(name, e);
  if (static_cast<std::uint64_t>(m.width) * m.point_step > m.row_step) {
    return fail(name, "row_step " + std::to_string(m.row_step) + " is less than " + std::to_string(m.width) +
                          " points of " + std::to_string(m.point_step) + " bytes (width x point_step)");
  }
  const std::uint64_t need = static_cast<std::uint64_t>(m.height) * m.row_step;
  if (m.data.size() < need) {
    return fail(name, "data holds " + std::to_string(m.data.size()) + " bytes; " + std::to_string(m.height) + " rows of " +
                          std::to_string(m.row_step) + " bytes need " + std::to_string(need));
  }
  begin_cloud(out, static_cast<std::size_t>(points), roles);
  // (No points: done, whatever the height. Four billion empty rows walked
  // one by one were the fuzzer's timeout.)
  if (points == 0) return Status::ok();
  for (const Field& f : roles) {
    if (f.role == Role::none) continue;
    std::size_t at = 0;
    const char* why = nullptr;
    switch (f.type) {
      case Scalar::i8: why = copy_field<std::int8_t>(m, f, out, at); break;
      case Scalar::u8: why = copy_field<std::uint8_t>(m, f, out, at); break;
      case Scalar::i16: why = copy_field<std::int16_t>(m, f, out, at); break;
      case Scalar::u16: why = copy_field<std::uint16_t>(m, f, out, at); break;
      case Scalar::i32: why = copy_field<std::int32_t>(m, f, out, at); break;
      case Scalar::u32: why = copy_field<std::uint32_t>(m, f, out, at); break;
      case Scalar::f32: why = copy_field<float>(m, f, out, at); break;
      case Scalar::f64: why = copy_field<double>(m, f, out, at); break;
    }
    if (why != nullptr) {
      out.size = 0;
      return fail(name, "point " + std::to_string(at + 1) + ": " + why);
    }
  }
  return Status::ok();
}

std::string_view cloud_format_name(CloudFormat f) noexcept {
  switch (f) {
    case CloudFormat::kitti_bin: return "KITTI .bin";
    case CloudFormat::pcd: return "PCD";
    case CloudFormat::ply: return "PLY";
  }
  return "?";
}

std::optional<CloudFormat> cloud_format_of(std::string_view path) noexcept {
  const std::size_t dot = path.rfind('.');
  if (dot == std::string_view::npos) return std::nullopt;
  std::string ext(path.substr(dot + 1));
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == "bin") return CloudFormat::kitti_bin;
  if (ext == "pcd") return CloudFormat::pcd;
  if (ext == "ply") return CloudFormat::ply;
  return std::nullopt;
}

Status read_cloud(std::span<const std::uint8_t> bytes, CloudFormat format, const std::string& name, PointCloud& out,
                  CloudScratch& scratch) {
  out.size = 0;
  Status st = Status::ok();
  switch (format) {
    case CloudFormat::kitti_bin: st = read_kitti(bytes, name, out); break;
    case CloudFormat::pcd: st = read_pcd(bytes, name, out, scratch); break;
    case CloudFormat::ply: st = read_ply(bytes, name, out); break;
  }
  if (!st) out.size = 0;  // whole or not at all
  return st;
}

Status load_cloud(const std::string& path, PointCloud& out, CloudScratch& scratch) {
  const auto format = cloud_format_of(path);
  if (!format) return Status::error(path + ": not a point-cloud file this reader knows (.bin KITTI, .pcd, .ply)");
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return Status::error(path + ": cannot open: " + std::strerror(errno));
  const auto size = static_cast<std::size_t>(in.tellg());
  in.seekg(0);
  if (scratch.bytes.size() < size) scratch.bytes.resize(size);
  if (size > 0 && !in.read(reinterpret_cast<char*>(scratch.bytes.data()), static_cast<std::streamsize>(size))) {
    return Status::error(path + ": cannot read");
  }
  return read_cloud(std::span<const std::uint8_t>(scratch.bytes.data(), size), *format, path, out, scratch);
}

}  // namespace trailnav::cloud
