// Point-cloud files (drivers/cloud): the real KITTI and SemanticKITTI scans;
// the same points written as PCD (ascii, binary, binary_compressed) and PLY
// (ascii, both binary byte orders, with another element around the
// vertices) read back alike; every malformed file refused with where and
// what; no heap once the cloud and scratch are sized.
#include <gtest/gtest.h>

#include <lzf.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "test_data.hpp"
#include "trailnav/drivers/cloud/cloud_file.hpp"
#include "trailnav/runtime/alloc_guard.hpp"

namespace trailnav::cloud {
namespace {

namespace fs = std::filesystem;

std::vector<std::uint8_t> as_bytes(const std::string& s) { return {s.begin(), s.end()}; }

void put(std::vector<std::uint8_t>& out, const void* p, std::size_t n, bool big = false) {
  const auto* b = static_cast<const std::uint8_t*>(p);
  for (std::size_t k = 0; k < n; ++k) out.push_back(big ? b[n - 1 - k] : b[k]);
}

// The first `n` points of the real SemanticKITTI scan, with a ring and a time made up for them.
struct Sample {
  std::vector<float> x, y, z, i;
  std::vector<std::uint16_t> ring;
  std::vector<double> t;
};
Sample sample(std::size_t n) {
  PointCloud c;
  CloudScratch s;
  EXPECT_TRUE(load_cloud(test::shared_data("semantickitti/000000.bin"), c, s));
  Sample out;
  for (std::size_t k = 0; k < n; ++k) {
    out.x.push_back(c.x[k]);
    out.y.push_back(c.y[k]);
    out.z.push_back(c.z[k]);
    out.i.push_back(c.intensity[k]);
    out.ring.push_back(static_cast<std::uint16_t>(k % 64));
    out.t.push_back(1e-5 * static_cast<double>(k));
  }
  return out;
}

void expect_same(const PointCloud& c, const Sample& s, const char* what) {
  ASSERT_EQ(c.size, s.x.size()) << what;
  EXPECT_TRUE(c.has_intensity && c.has_ring && c.has_time) << what;
  for (std::size_t k = 0; k < c.size; ++k) {
    ASSERT_FLOAT_EQ(c.x[k], s.x[k]) << what << " point " << k;
    ASSERT_FLOAT_EQ(c.y[k], s.y[k]) << what << " point " << k;
    ASSERT_FLOAT_EQ(c.z[k], s.z[k]) << what << " point " << k;
    ASSERT_FLOAT_EQ(c.intensity[k], s.i[k]) << what << " point " << k;
    ASSERT_EQ(c.ring[k], s.ring[k]) << what << " point " << k;
    ASSERT_DOUBLE_EQ(c.time[k], s.t[k]) << what << " point " << k;
  }
}

constexpr const char* kPcdHeader =
    "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity rgb ring time\n"
    "SIZE 4 4 4 4 4 2 8\nTYPE F F F F U U F\nCOUNT 1 1 1 1 1 1 1\nWIDTH %zu\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
    "POINTS %zu\nDATA %s\n";

std::vector<std::uint8_t> pcd(const Sample& s, const char* data) {
  char head[512];
  std::snprintf(head, sizeof head, kPcdHeader, s.x.size(), s.x.size(), data);
  std::vector<std::uint8_t> out = as_bytes(head);
  const std::uint32_t rgb = 0x00ff8800;
  if (std::strcmp(data, "ascii") == 0) {
    for (std::size_t k = 0; k < s.x.size(); ++k) {
      char line[256];
      std::snprintf(line, sizeof line, "%.9g %.9g %.9g %.9g %u %u %.17g\n", static_cast<double>(s.x[k]),
                    static_cast<double>(s.y[k]), static_cast<double>(s.z[k]), static_cast<double>(s.i[k]), rgb, s.ring[k], s.t[k]);
      const auto b = as_bytes(line);
      out.insert(out.end(), b.begin(), b.end());
    }
    return out;
  }
  std::vector<std::uint8_t> body;
  if (std::strcmp(data, "binary") == 0) {
    for (std::size_t k = 0; k < s.x.size(); ++k) {
      put(body, &s.x[k], 4), put(body, &s.y[k], 4), put(body, &s.z[k], 4), put(body, &s.i[k], 4);
      put(body, &rgb, 4), put(body, &s.ring[k], 2), put(body, &s.t[k], 8);
    }
    out.insert(out.end(), body.begin(), body.end());
    return out;
  }
  // binary_compressed: each field's values together, then LZF.
  for (std::size_t k = 0; k < s.x.size(); ++k) put(body, &s.x[k], 4);
  for (std::size_t k = 0; k < s.x.size(); ++k) put(body, &s.y[k], 4);
  for (std::size_t k = 0; k < s.x.size(); ++k) put(body, &s.z[k], 4);
  for (std::size_t k = 0; k < s.x.size(); ++k) put(body, &s.i[k], 4);
  for (std::size_t k = 0; k < s.x.size(); ++k) put(body, &rgb, 4);
  for (std::size_t k = 0; k < s.x.size(); ++k) put(body, &s.ring[k], 2);
  for (std::size_t k = 0; k < s.x.size(); ++k) put(body, &s.t[k], 8);
  std::vector<std::uint8_t> packed(body.size() + body.size() / 16 + 64);
  const unsigned n = lzf_compress(body.data(), static_cast<unsigned>(body.size()), packed.data(), static_cast<unsigned>(packed.size()));
  EXPECT_GT(n, 0u);
  const auto sizes = std::array<std::uint32_t, 2>{n, static_cast<std::uint32_t>(body.size())};
  put(out, &sizes[0], 4), put(out, &sizes[1], 4);
  out.insert(out.end(), packed.begin(), packed.begin() + n);
  return out;
}

// A face element before the vertices (with a list), the vertices, an edge element after.
std::vector<std::uint8_t> ply(const Sample& s, const char* format) {
  const bool ascii = std::strcmp(format, "ascii") == 0, big = std::strcmp(format, "binary_big_endian") == 0;
  char head[640];
  std::snprintf(head, sizeof head,
                "ply\nformat %s 1.0\ncomment written by a test\nelement face 2\nproperty list uchar int vertex_indices\n"
                "element vertex %zu\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\n"
                "property float intensity\nproperty ushort ring\nproperty double timestamp\nelement edge 1\n"
                "property int vertex1\nproperty int vertex2\nend_header\n",
                format, s.x.size());
  std::vector<std::uint8_t> out = as_bytes(head);
  if (ascii) {
    std::string text = "3 0 1 2\n2 4 5\n";
    for (std::size_t k = 0; k < s.x.size(); ++k) {
      char line[256];
      std::snprintf(line, sizeof line, "%.9g %.9g %.9g 200 %.9g %u %.17g\n", static_cast<double>(s.x[k]), static_cast<double>(s.y[k]),
                    static_cast<double>(s.z[k]), static_cast<double>(s.i[k]), s.ring[k], s.t[k]);
      text += line;
    }
    text += "0 1\n";
    const auto b = as_bytes(text);
    out.insert(out.end(), b.begin(), b.end());
    return out;
  }
  for (const std::vector<std::int32_t>& face : {std::vector<std::int32_t>{0, 1, 2}, std::vector<std::int32_t>{4, 5}}) {
    const auto n = static_cast<std::uint8_t>(face.size());
    out.push_back(n);
    for (std::int32_t v : face) put(out, &v, 4, big);
  }
  const std::uint8_t red = 200;
  for (std::size_t k = 0; k < s.x.size(); ++k) {
    put(out, &s.x[k], 4, big), put(out, &s.y[k], 4, big), put(out, &s.z[k], 4, big), put(out, &red, 1, big);
    put(out, &s.i[k], 4, big), put(out, &s.ring[k], 2, big), put(out, &s.t[k], 8, big);
  }
  const std::int32_t e0 = 0, e1 = 1;
  put(out, &e0, 4, big), put(out, &e1, 4, big);
  return out;
}

TEST(CloudFile, RealKittiAndSemanticKittiScans) {
  PointCloud c;
  CloudScratch s;
  ASSERT_TRUE(load_cloud(test::shared_data("semantickitti/000000.bin"), c, s));
  EXPECT_EQ(c.size, 123389u);  // the data's README
  EXPECT_TRUE(c.has_intensity);
  EXPECT_FALSE(c.has_ring);
  float max_r = 0.0f;
  for (std::size_t k = 0; k < c.size; ++k) max_r = std::max(max_r, std::hypot(c.x[k], c.y[k]));
  EXPECT_GT(max_r, 50.0f);
  EXPECT_LT(max_r, 130.0f);
  ASSERT_TRUE(load_cloud(test::shared_data("kitti/000000.bin"), c, s));
  EXPECT_EQ(c.size * 16, fs::file_size(test::shared_data("kitti/000000.bin")));
}

TEST(CloudFile, EveryEncodingOfTheSamePointsReadsTheSame) {
  const Sample s = sample(2000);
  PointCloud c;
  CloudScratch scratch;
  for (const char* data : {"ascii", "binary", "binary_compressed"}) {
    const auto bytes = pcd(s, data);
    const Status st = read_cloud(bytes, CloudFormat::pcd, std::string("x.pcd ") + data, c, scratch);
    ASSERT_TRUE(st) << st.message();
    expect_same(c, s, data);
  }
  for (const char* format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    const auto bytes = ply(s, format);
    const Status st = read_cloud(bytes, CloudFormat::ply, std::string("x.ply ") + format, c, scratch);
    ASSERT_TRUE(st) << st.message();
    expect_same(c, s, format);
  }
}

// PCL pads binary records with fields named "_" and leaves them out of
// binary_compressed data: both read.
TEST(CloudFile, PclsPaddingFieldsInBinaryAndCompressedData) {
  const std::string head = "FIELDS x y z _ intensity\nSIZE 4 4 4 1 4\nTYPE F F F U F\nCOUNT 1 1 1 4 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\n";
  std::vector<std::uint8_t> binary = as_bytes(head + "DATA binary\n");
  const float p[2][4] = {{1.0f, 2.0f, 3.0f, 9.0f}, {4.0f, 5.0f, 6.0f, 8.0f}};
  for (const auto& q : p) {
    put(binary, &q[0], 12);
    binary.insert(binary.end(), 4, 0xee);  // the padding
    put(binary, &q[3], 4);
  }
  std::vector<std::uint8_t> columns;
  for (int f = 0; f < 4; ++f) {
    for (const auto& q : p) put(columns, &q[f], 4);
  }
  std::vector<std::uint8_t> compressed = as_bytes(head + "DATA binary_compressed\n");
  std::vector<std::uint8_t> packed(columns.size() + 64);
  const unsigned n = lzf_compress(columns.data(), static_cast<unsigned>(columns.size()), packed.data(), static_cast<unsigned>(packed.size()));
  const std::uint32_t sizes[2] = {n, static_cast<std::uint32_t>(columns.size())};
  put(compressed, &sizes[0], 4), put(compressed, &sizes[1], 4);
  compressed.insert(compressed.end(), packed.begin(), packed.begin() + n);
  PointCloud c;
  CloudScratch s;
  for (const auto* b : {&binary, &compressed}) {
    const Status st = read_cloud(*b, CloudFormat::pcd, "padded.pcd", c, s);
    ASSERT_TRUE(st) << st.message();
    ASSERT_EQ(c.size, 2u);
    EXPECT_FLOAT_EQ(c.x[1], 4.0f);
    EXPECT_FLOAT_EQ(c.z[0], 3.0f);
    EXPECT_FLOAT_EQ(c.intensity[0], 9.0f);
    EXPECT_FLOAT_EQ(c.intensity[1], 8.0f);
  }
}

// A PLY element without properties holds no bytes however many it counts:
// read at once (the cloud fuzzer's timeout walked billions of them).
TEST(CloudFile, APlyElementWithoutPropertiesTakesNoTime) {
  std::vector<std::uint8_t> b = as_bytes(
      "ply\nformat binary_little_endian 1.0\nelement marker 400000000000\nelement vertex 2\nproperty float x\n"
      "property float y\nproperty float z\nend_header\n");
  const float p[6] = {1.0f, 2.0f, 3.0f, 4.0f, 5.0f, 6.0f};
  put(b, p, sizeof p);
  PointCloud c;
  CloudScratch s;
  const auto start = std::chrono::steady_clock::now();
  const Status st = read_cloud(b, CloudFormat::ply, "markers.ply", c, s);
  ASSERT_TRUE(st) << st.message();
  ASSERT_EQ(c.size, 2u);
  EXPECT_FLOAT_EQ(c.z[1], 6.0f);
  // (Walking the elements took minutes; a bound no loaded machine comes near.)
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
}

TEST(CloudFile, MalformedFilesAreRefusedWithWhereAndWhat) {
  const Sample s = sample(10);
  PointCloud c;
  CloudScratch scratch;
  auto error = [&](const std::vector<std::uint8_t>& b, CloudFormat f) -> std::string {
    EXPECT_TRUE(read_cloud(pcd(s, "binary"), CloudFormat::pcd, "ok.pcd", c, scratch));
    const Status st = read_cloud(b, f, "bad", c, scratch);
    EXPECT_FALSE(st);
    EXPECT_EQ(c.size, 0u) << "a file is read whole or not at all";
    return std::string(st.message());
  };
  auto has = [](const std::string& e, const char* what) {
    EXPECT_NE(e.find(what), std::string::npos) << "'" << e << "' should say " << what;
  };
  has(error(std::vector<std::uint8_t>(17, 0), CloudFormat::kitti_bin), "16 bytes a point");
  auto b = pcd(s, "binary");
  b.resize(b.size() - 3);
  has(error(b, CloudFormat::pcd), "the data holds");
  // binary_compressed: cut short, or its inflated size not the points' (PCD
  // carries no checksum: a changed byte inside the LZF data reads as other values).
  b = pcd(s, "binary_compressed");
  b.resize(b.size() - 5);
  has(error(b, CloudFormat::pcd), "cut short");
  b = pcd(s, "binary_compressed");
  const std::string text(b.begin(), b.end());
  const std::size_t body = text.find("DATA binary_compressed\n") + 23;
  b[body + 4] ^= 0x01;  // the inflated size
  has(error(b, CloudFormat::pcd), "binary_compressed data of");
  has(error(as_bytes("FIELDS a b c\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 3\n"), CloudFormat::pcd),
      "no field x, y and z");
  has(error(as_bytes("FIELDS x y z\nSIZE 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n1 2 3\n"), CloudFormat::pcd),
      "header line 2: SIZE gives 2 values for 3 fields");
  has(error(as_bytes("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nHEIGHT 2\nPOINTS 3\nDATA ascii\n"), CloudFormat::pcd),
      "is not POINTS");
  has(error(as_bytes("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 2\nDATA ascii\n1 2 3\n4 5\n"), CloudFormat::pcd),
      "point 2: fewer values");
  has(error(as_bytes("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA ascii\n1 two 3\n"), CloudFormat::pcd),
      "not a number");
  has(error(as_bytes("FIELDS x y z ring\nSIZE 4 4 4 4\nTYPE F F F F\nPOINTS 1\nDATA ascii\n1 2 3 2.5\n"), CloudFormat::pcd),
      "ring that is not a whole number");
  has(error(as_bytes("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nDATA lzma\n"), CloudFormat::pcd), "DATA 'lzma'");
  has(error(as_bytes("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\n"), CloudFormat::pcd), "no DATA line");
  has(error(as_bytes("FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 1\nHEADROOM 3\nDATA ascii\n"), CloudFormat::pcd),
      "header line 5: unknown header key 'HEADROOM'");
  has(error(as_bytes("plyx\n"), CloudFormat::ply), "not a PLY file");
  has(error(as_bytes("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"), CloudFormat::ply), "no end_header");
  has(error(as_bytes("ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n"), CloudFormat::ply),
      "unknown type 'quad'");
  has(error(as_bytes("ply\nformat ascii 1.0\nelement face 1\nproperty float x\nend_header\n1\n"), CloudFormat::ply),
      "no vertex element");
  b = ply(s, "binary_little_endian");
  b.resize(b.size() - 20);
  has(error(b, CloudFormat::ply), "the data ends in vertex 10 of 10");
  EXPECT_NE(load_cloud("/nonexistent/scan.pcd", c, scratch).message().find("cannot open"), std::string::npos);
  EXPECT_NE(load_cloud("scan.las", c, scratch).message().find("not a point-cloud file"), std::string::npos);
}

// Sized for the sensor up front, reading touches no heap: the real scan, and
// the compressed PCD (its inflation into the scratch included).
// The sample as a sensor_msgs/PointCloud2: `rows` rows, each padded to
// row_step with `row_pad` bytes; fields x y z intensity (float32), a
// two-byte gap, ring (uint16), a field no role knows, time as float64
// seconds or (ns) as Ouster's uint32 `t`.
struct Pc2 {
  std::vector<PointFieldView> fields;
  std::vector<std::uint8_t> data;
  PointCloud2View view;
};
Pc2 pointcloud2(const Sample& s, std::uint32_t rows, bool big, std::uint32_t row_pad, bool ns) {
  Pc2 m;
  m.fields = {{"x", 0, 7, 1}, {"y", 4, 7, 1}, {"z", 8, 7, 1}, {"intensity", 12, 7, 1}, {"ring", 18, 4, 1},
              {"ambient", 20, 4, 1}, {ns ? "t" : "time", 24, static_cast<std::uint8_t>(ns ? 6 : 8), 1}};
  const std::uint32_t step = 32;
  const auto width = static_cast<std::uint32_t>(s.x.size() / rows);
  for (std::uint32_t r = 0; r < rows; ++r) {
    for (std::uint32_t c = 0; c < width; ++c) {
      const std::size_t k = static_cast<std::size_t>(r) * width + c;
      const std::uint16_t gap = 0xabcd, ambient = 7;
      put(m.data, &s.x[k], 4, big), put(m.data, &s.y[k], 4, big), put(m.data, &s.z[k], 4, big);
      put(m.data, &s.i[k], 4, big), put(m.data, &gap, 2, big), put(m.data, &s.ring[k], 2, big);
      put(m.data, &ambient, 2, big);
      m.data.insert(m.data.end(), 2, 0);
      if (ns) {
        const auto t = static_cast<std::uint32_t>(std::llround(s.t[k] * 1e9));
        put(m.data, &t, 4, big);
        m.data.insert(m.data.end(), 4, 0);
      } else {
        put(m.data, &s.t[k], 8, big);
      }
    }
    m.data.insert(m.data.end(), row_pad, 0xee);
  }
  m.view.height = rows;
  m.view.width = width;
  m.view.fields = m.fields;
  m.view.is_bigendian = big;
  m.view.point_step = step;
  m.view.row_step = width * step + row_pad;
  m.view.data = m.data;
  return m;
}

// ROS 2's point cloud message, as a lidar's ROS driver publishes it: the
// same points as the files, organised or not, either byte order, rows
// padded, times in seconds or nanoseconds.
TEST(CloudFile, PointCloud2MessagesReadAsTheFiles) {
  Sample s = sample(2048);
  PointCloud c;
  for (const bool big : {false, true}) {
    for (const std::uint32_t rows : {1u, 64u}) {
      const Pc2 m = pointcloud2(s, rows, big, rows == 1 ? 0 : 12, false);
      const Status st = read_pointcloud2(m.view, "/points", c);
      ASSERT_TRUE(st) << st.message();
      expect_same(c, s, big ? "big-endian PointCloud2" : "PointCloud2");
    }
  }
  // Ouster's `t`: uint32 nanoseconds.
  const Pc2 m = pointcloud2(s, 16, false, 0, true);
  ASSERT_TRUE(read_pointcloud2(m.view, "/ouster/points", c));
  for (std::size_t k = 0; k < c.size; ++k) {
    ASSERT_NEAR(c.time[k], s.t[k], 1e-9) << "point " << k;
  }
  // The real scan whole, as a PointCloud2 of x y z intensity.
  PointCloud file;
  CloudScratch scratch;
  ASSERT_TRUE(load_cloud(test::shared_data("semantickitti/000000.bin"), file, scratch));
  const std::vector<PointFieldView> kitti{{"x", 0, 7, 1}, {"y", 4, 7, 1}, {"z", 8, 7, 1}, {"intensity", 12, 7, 1}};
  PointCloud2View v;
  v.width = static_cast<std::uint32_t>(file.size);
  v.fields = kitti;
  v.point_step = 16;
  v.row_step = 16 * v.width;
  v.data = std::span<const std::uint8_t>(scratch.bytes.data(), file.size * 16);
  ASSERT_TRUE(read_pointcloud2(v, "/kitti", c));
  ASSERT_EQ(c.size, file.size);
  EXPECT_EQ(std::memcmp(c.x.data(), file.x.data(), c.size * 4), 0);
  EXPECT_EQ(std::memcmp(c.z.data(), file.z.data(), c.size * 4), 0);
  EXPECT_EQ(std::memcmp(c.intensity.data(), file.intensity.data(), c.size * 4), 0);
  EXPECT_FALSE(c.has_ring || c.has_time);
}

TEST(CloudFile, MalformedPointCloud2MessagesAreRefusedWithWhat) {
  const Sample s = sample(64);
  PointCloud c;
  auto refused = [&](const PointCloud2View& v, const std::string& words) {
    c.size = 7;
    const Status st = read_pointcloud2(v, "/points", c);
    EXPECT_FALSE(st) << words;
    EXPECT_NE(st.message().find(words), std::string::npos) << st.message();
    EXPECT_EQ(st.message().rfind("/points: ", 0), 0u) << st.message();
    EXPECT_EQ(c.size, 0u);
  };
  Pc2 m = pointcloud2(s, 1, false, 0, false);
  ASSERT_TRUE(read_pointcloud2(m.view, "/points", c));
  auto with_field = [&](std::size_t k, PointFieldView f) {
    std::vector<PointFieldView> fields = m.fields;
    fields[k] = f;
    return fields;
  };
  std::vector<PointFieldView> f = with_field(0, {"x", 0, 9, 1});
  PointCloud2View v = m.view;
  v.fields = f;
  refused(v, "field 'x': datatype 9 is not one of PointField's");
  f = with_field(2, {"z", 8, 7, 0});
  v.fields = f;
  refused(v, "field 'z': count 0");
  f = with_field(3, {"intensity", 30, 7, 1});
  v.fields = f;
  refused(v, "field 'intensity' at offset 30 (4 bytes) reaches past the point's 32 bytes");
  f = with_field(2, {"height", 8, 7, 1});
  v.fields = f;
  refused(v, "no field x, y and z");
  v = m.view;
  v.row_step = 31 * v.width;
  refused(v, "row_step 1984 is less than 64 points of 32 bytes");
  v = m.view;
  v.data = v.data.first(v.data.size() - 1);
  refused(v, "data holds 2047 bytes; 1 rows of 2048 bytes need 2048");
  v = m.view;
  v.height = 1u << 13;
  v.width = 1u << 12;
  refused(v, "8192 x 4096 points; a cloud holds at most 16777216");
  // No points in four billion rows (the fuzzer's timeout: each empty row was walked): an empty cloud, at once.
  v = m.view;
  v.height = 0xf7000202u;
  v.width = 0;
  v.row_step = 0;
  ASSERT_TRUE(read_pointcloud2(v, "/points", c));
  EXPECT_EQ(c.size, 0u);
  // A ring that is no laser index.
  f = with_field(4, {"ring", 0, 7, 1});  // x's float bytes (a real point's, metres) as the ring
  v = m.view;
  v.fields = f;
  refused(v, "point 1: a ring that is not a whole number from 0 to 65535");
}

TEST(CloudFile, SizedUpFrontReadingTouchesNoHeap) {
  const Sample s = sample(5000);
  const auto compressed = pcd(s, "binary_compressed");
  const auto binary_ply = ply(s, "binary_little_endian");
  PointCloud c(130000);
  CloudScratch scratch;
  scratch.bytes.resize(130000 * 16);
  scratch.inflated.resize(130000 * 30);
  const Pc2 message = pointcloud2(s, 50, true, 4, true);
  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("cloud");
  ASSERT_TRUE(alloc_guard::arm());
  const Status a = read_cloud(compressed, CloudFormat::pcd, "c.pcd", c, scratch);
  const Status b = read_cloud(binary_ply, CloudFormat::ply, "b.ply", c, scratch);
  const Status p = read_pointcloud2(message.view, "/points", c);
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_TRUE(a) << a.message();
  EXPECT_TRUE(b) << b.message();
  EXPECT_TRUE(p) << p.message();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
}

}  // namespace
}  // namespace trailnav::cloud
