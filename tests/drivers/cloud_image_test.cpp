// Point clouds as range images (drivers/cloud/cloud_image.hpp): rows from a
// ring field or inferred from the elevation with a sensor's ring layout,
// columns from the azimuth, every point accounted for (a cell's second
// point in the second layer, further ones counted), no heap.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <map>
#include <numbers>
#include <tuple>

#include "test_data.hpp"
#include "trailnav/drivers/cloud/cloud_file.hpp"
#include "trailnav/drivers/cloud/cloud_image.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/runtime/alloc_guard.hpp"
#include "trailnav/runtime/config.hpp"

namespace trailnav::cloud {
namespace {

PointCloud points(const std::vector<std::array<float, 3>>& xyz, const std::vector<int>& rings = {}) {
  PointCloud c(xyz.size());
  c.size = xyz.size();
  for (std::size_t k = 0; k < xyz.size(); ++k) {
    c.x[k] = xyz[k][0], c.y[k] = xyz[k][1], c.z[k] = xyz[k][2];
    c.intensity[k] = 0.5f;
  }
  c.has_intensity = true;
  if (!rings.empty()) {
    c.has_ring = true;
    for (std::size_t k = 0; k < rings.size(); ++k) c.ring[k] = static_cast<std::uint16_t>(rings[k]);
  }
  return c;
}

// A point at `elevation_deg` and `azimuth_deg`, 10 m away.
std::array<float, 3> at(double elevation_deg, double azimuth_deg, double range = 10.0) {
  const double e = elevation_deg * std::numbers::pi / 180.0, a = azimuth_deg * std::numbers::pi / 180.0;
  return {static_cast<float>(range * std::cos(e) * std::cos(a)), static_cast<float>(range * std::cos(e) * std::sin(a)),
          static_cast<float>(range * std::sin(e))};
}

TEST(CloudImage, RowsFromTheElevationOrTheRingFieldColumnsFromTheAzimuth) {
  // Four rings numbered out of elevation order, as Velodyne's lasers are.
  RingLayout l;
  l.name = "test";
  l.elevation_deg = {-1.0f, 3.0f, -5.0f, 1.0f};  // rows: ring 2 (-5), ring 0 (-1), ring 3 (1), ring 1 (3)
  l.columns = 360;
  CloudImager imager(l, 2, {255.0f, 0.1});
  EXPECT_EQ(imager.shape().rings, 4);
  EXPECT_EQ(imager.shape().max_columns, 360);
  velodyne::RangeImage image(imager.shape());
  CloudImageStats st;
  // By elevation: -4.2 deg is nearest -5 (row 0), 0.1 deg nearest 1 (row 2: -1 and 1 are 1.1 and 0.9 away).
  imager.fill(points({at(-4.2, 10.5), at(0.1, 90.5), at(2.6, 359.6)}), image, st);
  EXPECT_EQ(st.inferred, 3u);
  EXPECT_EQ(st.placed, 3u);
  EXPECT_TRUE(image.at(0, 0, 10).valid());
  EXPECT_TRUE(image.at(0, 2, 90).valid());
  EXPECT_TRUE(image.at(0, 3, 359).valid());
  EXPECT_NEAR(image.at(0, 0, 10).intensity, 127.5f, 1e-3f);
  EXPECT_NEAR(image.at(0, 2, 90).azimuth, 90.5 * std::numbers::pi / 180.0, 1e-4);
  EXPECT_NEAR(image.at(0, 2, 90).distance, 10.0f, 1e-4f);
  // The file's ring wins over the elevation; a ring beyond the layout is counted.
  imager.fill(points({at(-4.2, 10.5), at(0.1, 90.5), at(2.6, 200.2)}, {1, 2, 7}), image, st);
  EXPECT_EQ(st.inferred, 0u);
  EXPECT_EQ(st.bad_ring, 1u);
  EXPECT_TRUE(image.at(0, 3, 10).valid());  // ring 1: row 3
  EXPECT_TRUE(image.at(0, 0, 90).valid());  // ring 2: row 0
}

TEST(CloudImage, EveryPointIsAccountedFor) {
  RingLayout l = uniform_ring_layout("u", 2, -1.0, 1.0, 100);
  CloudImager two(l, 2), one(l, 1);
  velodyne::RangeImage image2(two.shape()), image1(one.shape());
  CloudImageStats st;
  // Three points in one cell, an invalid one, one elsewhere.
  const PointCloud c = points({at(-1.0, 5.0), at(-1.0, 5.1, 12.0), at(-1.0, 5.2, 15.0), {NAN, 0.0f, 0.0f}, {0, 0, 0}, at(1.0, 50.0)});
  two.fill(c, image2, st);
  EXPECT_EQ(st.points, 6u);
  EXPECT_EQ(st.placed, 2u);
  EXPECT_EQ(st.second, 1u);
  EXPECT_EQ(st.collisions, 1u);
  EXPECT_EQ(st.invalid, 2u);
  EXPECT_EQ(st.placed + st.second + st.collisions + st.invalid + st.bad_ring, st.points);
  EXPECT_NEAR(image2.at(1, 0, 1).distance, 12.0f, 1e-4f);
  EXPECT_EQ(image2.points, 3);
  one.fill(c, image1, st);
  EXPECT_EQ(st.second, 0u);
  EXPECT_EQ(st.collisions, 2u);
}

// The real SemanticKITTI scan: the rows inferred from the elevation
// against those found from the order of the points (each laser's points
// come one after another, as the KITTI loader uses), with three layouts:
// the scan's own lasers' median elevations, the HDL-64E's nominal one, and
// another HDL-64E S2 unit's calibration.
TEST(CloudImage, ElevationRowsOnARealHdl64eScan) {
  PointCloud c;
  CloudScratch s;
  ASSERT_TRUE(load_cloud(test::shared_data("semantickitti/000000.bin"), c, s));
  // Rows from the order of the points: a new laser where the azimuth wraps
  // after most of a turn (as perception/kitti.cpp does), sorted by median elevation.
  std::vector<int> laser(c.size, 0);
  int current = 0;
  double swept = 0.0, prev = std::atan2(c.y[0], c.x[0]);
  for (std::size_t k = 1; k < c.size; ++k) {
    const double a = std::atan2(c.y[k], c.x[k]);
    double d = a - prev;
    if (d < -std::numbers::pi) d += 2 * std::numbers::pi;
    if (d > std::numbers::pi) d -= 2 * std::numbers::pi;
    if (prev < 0.0 && a >= 0.0 && swept > 1.5 * std::numbers::pi) {
      ++current;
      swept = 0.0;
    }
    swept += std::fabs(d);
    prev = a;
    laser[k] = current;
  }
  ASSERT_EQ(current + 1, 64);
  std::map<int, std::vector<float>> el;
  for (std::size_t k = 0; k < c.size; ++k) el[laser[k]].push_back(std::atan2(c.z[k], std::hypot(c.x[k], c.y[k])));
  RingLayout measured;  // each laser's median elevation in this scan, by its order
  measured.name = "this scan's lasers' median elevations";
  measured.columns = 2083;
  std::vector<std::pair<float, int>> med;
  for (auto& [l, v] : el) {
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    med.push_back({v[v.size() / 2], l});
    measured.elevation_deg.push_back(static_cast<float>(static_cast<double>(v[v.size() / 2]) * 180.0 / std::numbers::pi));
  }
  std::sort(med.begin(), med.end());
  std::map<int, int> row_of;
  for (std::size_t r = 0; r < med.size(); ++r) row_of[med[r].second] = static_cast<int>(r);

  const auto nominal = ring_layout_preset("HDL-64E");
  ASSERT_TRUE(nominal);
  ASSERT_EQ(nominal->elevation_deg.size(), 64u);
  // An HDL-64E S2's own calibration (another unit than KITTI's).
  const auto cal = velodyne::load_calibration(test::shared_data("velodyne/calibration/ros_velodyne_64e_s2.1-sztaki.yaml"));
  ASSERT_TRUE(cal.calibration) << cal.error;
  const RingLayout unit = ring_layout_from_calibration(*cal.calibration, "an HDL-64E S2's calibration (sztaki)", 2083);
  for (const RingLayout* layout : {static_cast<const RingLayout*>(&measured), &*nominal, &unit}) {
    CloudImager imager(*layout, 2, {255.0f, 0.1});
    velodyne::RangeImage image(imager.shape());
    CloudImageStats st;
    imager.fill(c, image, st);
    EXPECT_EQ(st.placed + st.second + st.collisions + st.invalid + st.bad_ring, st.points);
    EXPECT_EQ(st.inferred, st.points - st.invalid);
    std::uint64_t same = 0, within_one = 0, n = 0;
    for (std::size_t k = 0; k < c.size; ++k) {
      const float h = std::hypot(c.x[k], c.y[k]);
      if (!(h > 0.0f)) continue;
      const int a = imager.row_of_elevation(c.z[k], h), b = row_of[laser[k]];
      ++n;
      same += a == b ? 1u : 0u;
      within_one += std::abs(a - b) <= 1 ? 1u : 0u;
    }
    const double share = static_cast<double>(same) / static_cast<double>(n);
    const double near = static_cast<double>(within_one) / static_cast<double>(n);
    std::printf("[ cloud ] %s: %llu points in layer 0, %llu in layer 1, %llu beyond; rows from the elevation agree "
                "with those from the order for %.3f of the points, within one ring %.3f\n",
                layout->name.c_str(), static_cast<unsigned long long>(st.placed), static_cast<unsigned long long>(st.second),
                static_cast<unsigned long long>(st.collisions), share, near);
    // Even with the lasers' own median elevations a point's elevation from
    // the origin names its laser exactly for only 0.41 of the points (within
    // one ring 0.90): the HDL-64E's lasers sit at different heights and its
    // rings are a third of a degree apart, so near points' elevations cross
    // into the next ring's. Elevation alone is not enough for it
    // (docs/pointcloud.md): measured here, to be bettered.
    if (layout == &measured) {
      EXPECT_GT(near, 0.88);
    }
  }
}

// The sensor's order (RingSource::order) on the real scans: the KITTI
// loader's image (perception/kitti.cpp, the same sweeps, ordered by median
// elevation, a cell's first point kept) is this one's first layer, cell
// for cell; this one also keeps each cell's second point (layer 1) and
// counts the rest.
TEST(CloudImage, TheSensorsOrderGivesTheKittiLoadersRows) {
  for (const char* file : {"kitti/000000.bin", "kitti/000001.bin", "semantickitti/000000.bin"}) {
    PointCloud c;
    CloudScratch s;
    ASSERT_TRUE(load_cloud(test::shared_data(file), c, s));
    RingLayout layout = *ring_layout_preset("HDL-64E");
    layout.columns = perception::kKittiColumns;
    CloudImager imager(layout, 2, {255.0f, 0.1, RingSource::order});
    velodyne::RangeImage mine(imager.shape()), kitti(perception::kitti_shape());
    CloudImageStats st;
    imager.fill(c, mine, st);
    std::vector<float> buffer;
    ASSERT_TRUE(perception::load_kitti_scan(test::shared_data(file), buffer, kitti));
    EXPECT_EQ(st.sweeps, 64u) << file;
    EXPECT_EQ(st.placed + st.second + st.collisions + st.invalid + st.bad_ring, st.points);
    std::uint64_t cells = 0, same = 0;
    for (int r = 0; r < 64; ++r) {
      for (int col = 0; col < perception::kKittiColumns; ++col) {
        const velodyne::RangeCell& a = kitti.at(0, r, col);
        const velodyne::RangeCell& b = mine.at(0, r, col);
        if (!a.valid() && !b.valid()) continue;
        ++cells;
        same += a.valid() && b.valid() && a.x == b.x && a.y == b.y && a.z == b.z ? 1u : 0u;
      }
    }
    std::printf("[ cloud ] %s in sensor order: %llu of %llu cells hold the KITTI loader's point; %llu second points "
                "kept in layer 1, %llu more counted\n",
                file, static_cast<unsigned long long>(same), static_cast<unsigned long long>(cells),
                static_cast<unsigned long long>(st.second), static_cast<unsigned long long>(st.collisions));
    EXPECT_GT(static_cast<double>(same) / static_cast<double>(cells), 0.99) << file;
  }
}

// Hesai's and Ouster's presets: ring 0 the top beam, as their drivers
// number the rings; points at each beam's elevation land in its row.
TEST(CloudImage, HesaiAndOusterPresetsPlaceEachBeamInItsRow) {
  const auto p40 = ring_layout_preset("Pandar40P");
  ASSERT_TRUE(p40);
  ASSERT_EQ(p40->elevation_deg.size(), 40u);
  EXPECT_FLOAT_EQ(p40->elevation_deg[0], 15.21f);
  EXPECT_FLOAT_EQ(p40->elevation_deg[39], -24.569f);
  EXPECT_EQ(p40->columns, 1800);
  const auto os1 = ring_layout_preset("OS1-64");
  ASSERT_TRUE(os1);
  ASSERT_EQ(os1->elevation_deg.size(), 64u);
  EXPECT_FLOAT_EQ(os1->elevation_deg[0], 22.5f);
  EXPECT_FLOAT_EQ(os1->elevation_deg[63], -22.5f);
  EXPECT_EQ(ring_layout_preset("OS0-128")->elevation_deg.size(), 128u);
  EXPECT_FLOAT_EQ(ring_layout_preset("OS2-32")->elevation_deg[31], -11.25f);
  EXPECT_FALSE(ring_layout_preset("OS3-64"));
  EXPECT_FALSE(ring_layout_preset("OS1-48"));
  for (const std::string& n : ring_layout_presets()) EXPECT_TRUE(ring_layout_preset(n)) << n;

  // The Pandar64's dense middle (beams 0.17 degrees apart), from the elevation alone.
  const RingLayout p64 = *ring_layout_preset("Pandar64");
  const auto rings = static_cast<int>(p64.elevation_deg.size());
  PointCloud c(static_cast<std::size_t>(rings) * 90);
  std::vector<int> ring_of;
  for (int r = 0; r < rings; ++r) {
    const double e = static_cast<double>(p64.elevation_deg[static_cast<std::size_t>(r)]) * std::numbers::pi / 180.0;
    for (int k = 0; k < 90; ++k) {
      const double a = k * 4.0 * std::numbers::pi / 180.0, d = 3.0 + 0.5 * k;
      c.x[c.size] = static_cast<float>(d * std::cos(e) * std::cos(a));
      c.y[c.size] = static_cast<float>(d * std::cos(e) * std::sin(a));
      c.z[c.size] = static_cast<float>(d * std::sin(e));
      ++c.size;
      ring_of.push_back(r);
    }
  }
  CloudImager imager(p64, 1, {1.0f, 0.1, RingSource::elevation});
  velodyne::RangeImage image(imager.shape());
  std::vector<PointPlace> places(c.size);
  CloudImageStats st;
  imager.fill(c, image, st, places);
  EXPECT_EQ(st.placed, c.size);
  std::size_t right = 0;
  for (std::size_t i = 0; i < c.size; ++i) {
    // Rows go from the lowest beam: ring r (0 the top) is row rings - 1 - r.
    right += places[i].outcome == PlaceOutcome::placed && places[i].row == rings - 1 - ring_of[i] ? 1u : 0u;
  }
  EXPECT_EQ(right, c.size);
}

TEST(CloudImage, ALayoutFileGivesTheUnitsOwnBeams) {
  const std::string path = ::testing::TempDir() + "/trailnav-layout.yaml";
  auto write = [&](const char* text) {
    std::FILE* f = std::fopen(path.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs(text, f);
    std::fclose(f);
  };
  write("lidar_layout:\n  name: OS1-32 gradient (unit 992)\n  columns: 2048\n"
        "  elevations_deg: [12.75, 9.8, 7.0, 2.35, 2.0, 1.6, -2.96, -15.32]\n");
  const RingLayout l = load_ring_layout(path);
  EXPECT_EQ(l.name, "OS1-32 gradient (unit 992)");
  EXPECT_EQ(l.columns, 2048);
  ASSERT_EQ(l.elevation_deg.size(), 8u);
  EXPECT_FLOAT_EQ(l.elevation_deg[7], -15.32f);
  write("lidar_layout:\n  columns: 2048\n  elevations_deg: [12.75, 95.0]\n");
  EXPECT_THROW(load_ring_layout(path), ConfigError);
  write("lidar_layout:\n  columns: 8\n  elevations_deg: [1.0]\n");
  EXPECT_THROW(load_ring_layout(path), ConfigError);
  write("lidar_layout:\n  columns: 1024\n  elevations: [1.0]\n");
  EXPECT_THROW(load_ring_layout(path), ConfigError);
  std::remove(path.c_str());
}

// Every cell of both layers, bit for bit.
bool same_cells(const velodyne::RangeImage& a, const velodyne::RangeImage& b, std::string& where) {
  if (a.columns() != b.columns() || a.rings() != b.rings() || a.layers() != b.layers()) {
    where = "shape";
    return false;
  }
  for (int layer = 0; layer < a.layers(); ++layer) {
    for (int r = 0; r < a.rings(); ++r) {
      for (int col = 0; col < a.columns(); ++col) {
        const velodyne::RangeCell &p = a.at(layer, r, col), &q = b.at(layer, r, col);
        if (std::memcmp(&p.x, &q.x, 7 * sizeof(float)) != 0 || p.kind != q.kind) {
          where = "layer " + std::to_string(layer) + " row " + std::to_string(r) + " column " + std::to_string(col);
          return false;
        }
      }
    }
  }
  return true;
}

// The imager clears only the cells its last fill of the same image wrote
// and the next does not: the image must be the one a fresh image gets,
// whatever the image held (another scan, the same scan, another imager's).
TEST(CloudImage, AnImageIsTheSameWhateverItHeldBefore) {
  std::vector<PointCloud> scans(3);
  CloudScratch s;
  const char* files[] = {"kitti/000000.bin", "kitti/000001.bin", "semantickitti/000000.bin"};
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(load_cloud(test::shared_data(files[k]), scans[static_cast<std::size_t>(k)], s));
  for (RingSource rings : {RingSource::order, RingSource::elevation}) {
    CloudImager imager(*ring_layout_preset("HDL-64E"), 2, {255.0f, 0.1, rings});
    velodyne::RangeImage reused(imager.shape());
    CloudImageStats st;
    // Through the scans and back, each fill compared with a fresh image's.
    for (int k : {0, 1, 2, 1, 1, 0, 2}) {
      const PointCloud& c = scans[static_cast<std::size_t>(k)];
      imager.fill(c, reused, st);
      CloudImager other(*ring_layout_preset("HDL-64E"), 2, {255.0f, 0.1, rings});
      velodyne::RangeImage fresh(other.shape());
      CloudImageStats fresh_st;
      other.fill(c, fresh, fresh_st);
      std::string where;
      EXPECT_TRUE(same_cells(reused, fresh, where)) << files[k] << ": differs at " << where;
      EXPECT_EQ(st.placed, fresh_st.placed);
      EXPECT_EQ(st.second, fresh_st.second);
      EXPECT_EQ(reused.points, fresh.points);
    }
    // An image another imager wrote in between is cleared whole.
    CloudImager other(*ring_layout_preset("HDL-64E"), 2, {255.0f, 0.1, rings});
    other.fill(scans[1], reused, st);
    imager.fill(scans[0], reused, st);
    velodyne::RangeImage fresh(imager.shape());
    CloudImager third(*ring_layout_preset("HDL-64E"), 2, {255.0f, 0.1, rings});
    third.fill(scans[0], fresh, st);
    std::string where;
    EXPECT_TRUE(same_cells(reused, fresh, where)) << "after another imager: differs at " << where;
  }
}

// Eight or four points at a time where the CPU has the lanes, the rest one
// by one: the same bits either way. The same scan with one point without a return
// in front puts every point in another lane (and other points in the tail).
TEST(CloudImage, LanesAndTheTailGiveTheSameCells) {
  PointCloud c;
  CloudScratch s;
  ASSERT_TRUE(load_cloud(test::shared_data("kitti/000001.bin"), c, s));
  for (std::size_t shift = 1; shift <= 3; ++shift) {
    PointCloud d(c.size + shift);
    d.size = c.size + shift;
    d.has_intensity = c.has_intensity;
    for (std::size_t k = 0; k < shift; ++k) d.x[k] = d.y[k] = d.z[k] = 0.0f;  // at the origin: invalid
    for (std::size_t k = 0; k < c.size; ++k) {
      d.x[k + shift] = c.x[k];
      d.y[k + shift] = c.y[k];
      d.z[k + shift] = c.z[k];
      d.intensity[k + shift] = c.intensity[k];
    }
    CloudImager a(*ring_layout_preset("HDL-64E"), 2, {255.0f, 0.1, RingSource::elevation});
    CloudImager b(*ring_layout_preset("HDL-64E"), 2, {255.0f, 0.1, RingSource::elevation});
    velodyne::RangeImage ia(a.shape()), ib(b.shape());
    CloudImageStats sa, sb;
    a.fill(c, ia, sa);
    b.fill(d, ib, sb);
    std::string where;
    EXPECT_TRUE(same_cells(ia, ib, where)) << "shifted by " << shift << ": differs at " << where;
    EXPECT_EQ(sb.invalid, sa.invalid + shift);
    EXPECT_EQ(sa.placed, sb.placed);
  }
  // Eight lanes (AVX2, where this CPU has it), four and one: the same cells.
  velodyne::RangeImage one_by_one(CloudImager(*ring_layout_preset("HDL-64E"), 2).shape());
  CloudImageStats st;
  CloudImageOptions o{255.0f, 0.1, RingSource::order};
  o.lanes = 1;
  CloudImager(*ring_layout_preset("HDL-64E"), 2, o).fill(c, one_by_one, st);
  for (int lanes : {4, 8}) {
    o.lanes = lanes;
    CloudImager imager(*ring_layout_preset("HDL-64E"), 2, o);
    velodyne::RangeImage image(imager.shape());
    imager.fill(c, image, st);
    std::string where;
    EXPECT_TRUE(same_cells(one_by_one, image, where)) << lanes << " lanes: differs at " << where;
  }
}

TEST(CloudImage, FillingTouchesNoHeap) {
  PointCloud c;
  CloudScratch s;
  ASSERT_TRUE(load_cloud(test::shared_data("semantickitti/000000.bin"), c, s));
  CloudImager imager(*ring_layout_preset("HDL-64E"), 2, {255.0f, 0.1, RingSource::order});
  velodyne::RangeImage image(imager.shape());
  CloudImageStats st;
  imager.fill(c, image, st);  // first touch of the image's pages
  std::vector<PointPlace> places(c.size);
  imager.index(c, st, places);  // (its per-point intensities sized here)
  alloc_guard::set_fatal(false);
  alloc_guard::mark_realtime_thread("cloud");
  ASSERT_TRUE(alloc_guard::arm());
  imager.fill(c, image, st);
  imager.fill(c, image, st);
  const ScanCells cells = imager.index(c, st, places);
  imager.fill(c, image, st, places);
  alloc_guard::disarm();
  alloc_guard::unmark_current_thread();
  EXPECT_EQ(alloc_guard::total_allocations(), 0u);
  EXPECT_GT(st.placed, 0u);
  EXPECT_NE(cells.first, nullptr);
}

// index() places every point as fill() does (the same places and counts),
// and each cell's first point is the one fill() wrote into layer 0.
TEST(CloudImage, TheCellsIndexHoldsWhatTheImageHolds) {
  PointCloud c;
  CloudScratch s;
  ASSERT_TRUE(load_cloud(test::shared_data("semantickitti/000000.bin"), c, s));
  for (const RingSource rings : {RingSource::order, RingSource::elevation}) {
    CloudImager imager(*ring_layout_preset("HDL-64E"), 2, {255.0f, 0.1, rings});
    velodyne::RangeImage image(imager.shape());
    std::vector<PointPlace> by_fill(c.size), by_index(c.size);
    CloudImageStats fs, is;
    imager.fill(c, image, fs, by_fill);
    const ScanCells cells = imager.index(c, is, by_index);
    EXPECT_EQ(fs.placed, is.placed);
    EXPECT_EQ(fs.second, is.second);
    EXPECT_EQ(fs.collisions, is.collisions);
    EXPECT_EQ(fs.invalid, is.invalid);
    EXPECT_EQ(fs.bad_ring, is.bad_ring);
    EXPECT_EQ(fs.inferred, is.inferred);
    EXPECT_GT(is.second, 1000u);  // (the scan has crowded cells)
    std::size_t places_differ = 0;
    for (std::size_t i = 0; i < c.size; ++i) {
      const PointPlace& a = by_fill[i];
      const PointPlace& b = by_index[i];
      places_differ += a.row == b.row && a.column == b.column && a.outcome == b.outcome && a.apart == b.apart ? 0u : 1u;
    }
    EXPECT_EQ(places_differ, 0u);
    std::size_t cells_differ = 0, held = 0;
    for (int r = 0; r < cells.rings; ++r) {
      for (int col = 0; col < cells.columns; ++col) {
        const std::int32_t k = cells.first[static_cast<std::size_t>(r) * static_cast<std::size_t>(cells.columns) +
                                           static_cast<std::size_t>(col)];
        const velodyne::RangeCell& cell = image.at(0, r, col);
        if (k < 0) {
          cells_differ += cell.valid() ? 1u : 0u;
          continue;
        }
        ++held;
        const auto i = static_cast<std::size_t>(k);
        const bool same = cell.valid() && cell.x == cells.x[i] && cell.y == cells.y[i] && cell.z == cells.z[i] &&
                          cell.distance == cells.distance[i] && cell.azimuth == cells.azimuth[i] &&
                          cell.intensity == cells.intensity[i];
        cells_differ += same ? 0u : 1u;
      }
    }
    EXPECT_EQ(cells_differ, 0u);
    EXPECT_EQ(held, is.placed);
  }
}

}  // namespace
}  // namespace trailnav::cloud
