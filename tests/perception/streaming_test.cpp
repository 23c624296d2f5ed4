// A revolution taken while it arrives (ObstaclePipeline::begin / advance /
// finish, what trailnavd's obstacle thread does) against the same revolution
// taken whole, and against the stages one by one (the offline tools): the
// maps must be the same bits, every cell of every model, however the
// revolution was cut into steps. On real data: KITTI scans with their rings
// moved around the image the way an HDL-64E's rotation corrections move
// them, and a real HDL-32E capture assembled packet by packet, each step
// taking the columns the assembler says are final.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <random>
#include <vector>

#include "test_data.hpp"
#include "trailnav/drivers/capture/capture_reader.hpp"
#include "trailnav/drivers/velodyne/calibration.hpp"
#include "trailnav/drivers/velodyne/packet.hpp"
#include "trailnav/drivers/velodyne/range_image.hpp"
#include "trailnav/drivers/velodyne/sensor_clock.hpp"
#include "trailnav/perception/kitti.hpp"
#include "trailnav/perception/obstacle_pipeline.hpp"

namespace trailnav::perception {
namespace {

std::unique_ptr<ObstaclePipeline> make_pipeline(const velodyne::RangeImageShape& shape) {
  ObstacleConfig config;
  config.compare_models = true;  // PW, PS and PC all compared
  auto made = ObstaclePipeline::create(config, shape);
  EXPECT_TRUE(made.pipeline) << made.error;
  return std::move(made.pipeline);
}

// Cells of every model's map that differ between two pipelines (bits of the
// log-odds, and the exported occupancy).
std::size_t differing_cells(const ObstaclePipeline& a, const ObstaclePipeline& b) {
  std::size_t differ = 0;
  for (int m = 0; m < kFusionModels; ++m) {
    const ObstacleMap* ma = a.map(static_cast<FusionModel>(m));
    const ObstacleMap* mb = b.map(static_cast<FusionModel>(m));
    if (ma == nullptr || mb == nullptr) {
      ADD_FAILURE() << "no map of model " << m;
      return 1;
    }
    const auto& ga = ma->grid();
    const auto& gb = mb->grid();
    if (ga.origin().x != gb.origin().x || ga.origin().y != gb.origin().y) return ga.cell_count();
    for (std::int32_t y = 0; y < ga.size_y(); ++y) {
      for (std::int32_t x = 0; x < ga.size_x(); ++x) {
        const CellIndex c{ga.origin().x + x, ga.origin().y + y};
        if (std::memcmp(&ga.at(c).logit, &gb.at(c).logit, sizeof(float)) != 0) ++differ;
      }
    }
    std::vector<std::int8_t> oa(ga.cell_count()), ob(gb.cell_count());
    ma->export_occupancy(oa);
    mb->export_occupancy(ob);
    if (oa != ob) ++differ;
  }
  return differ;
}

// Known cells of the configured map.
std::size_t known_cells(const ObstaclePipeline& p) {
  std::vector<std::int8_t> occupancy(p.map().grid().cell_count());
  p.map().export_occupancy(occupancy);
  std::size_t known = 0;
  for (std::int8_t v : occupancy) known += v >= 0;
  return known;
}

// A KITTI scan with each ring's points moved `shift(ring)` columns away from
// their own azimuth's column (kept in the cells), as an HDL-64E's lasers fire
// in one column and point into another.
velodyne::RangeImage fired_like_an_hdl64e(const velodyne::RangeImage& scan, int max_shift) {
  velodyne::RangeImage out(scan.shape());
  out.reset(scan.columns());
  out.mark_received(0, scan.columns());
  out.sequence = scan.sequence;
  out.start_ns = scan.start_ns;
  out.end_ns = scan.end_ns;
  out.rpm = scan.rpm;
  const int columns = scan.columns();
  for (int ring = 0; ring < scan.rings(); ++ring) {
    const int shift = (ring * 7) % (2 * max_shift + 1) - max_shift;
    for (int c = 0; c < columns; ++c) {
      const velodyne::RangeCell& cell = scan.at(0, ring, c);
      if (!cell.valid()) continue;
      out.at(0, ring, ((c + shift) % columns + columns) % columns) = cell;
    }
  }
  out.azimuth_spread = (max_shift + 1) * 2.0 * std::numbers::pi / columns;
  out.finish();
  return out;
}

TEST(ObstacleStreaming, KittiScansInAnyStepsGiveTheWholeRevolutionsMapsBitForBit) {
  const velodyne::RangeImageShape shape = kitti_shape();
  std::vector<velodyne::RangeImage> scans;
  std::vector<float> buffer;
  for (const char* name : {"kitti/000000.bin", "kitti/000001.bin"}) {
    velodyne::RangeImage scan(shape);
    ASSERT_TRUE(load_kitti_scan(test::shared_data(name), buffer, scan)) << name;
    scans.push_back(fired_like_an_hdl64e(scan, 20));
  }
  auto whole = make_pipeline(shape);
  auto streamed = make_pipeline(shape);
  auto stages = make_pipeline(shape);
  PoseTrack poses(256);
  std::mt19937 rng(42);
  std::uint64_t early = 0;
  for (int n = 0; n < 6; ++n) {
    velodyne::RangeImage& image = scans[static_cast<std::size_t>(n % 2)];
    image.sequence = static_cast<std::uint64_t>(n + 1);
    image.start_ns = n * 100'000'000LL;
    image.end_ns = image.start_ns + 99'000'000LL;
    image.finish();  // the column times for this revolution's span
    // The robot drives and turns while the lidar spins.
    poses.push({image.start_ns, 0.9 * n, 0.1 * n, 0.0, 0.01, -0.02, 0.05 * n});
    poses.push({image.end_ns, 0.9 * n + 0.8, 0.1 * n + 0.05, 0.0, 0.01, -0.02, 0.05 * n + 0.04});

    whole->process(image, &poses, nullptr);

    stages->align(image, &poses);
    stages->features();
    stages->update_maps(nullptr);

    // Steps of 1 to 400 columns, as the lidar's runs would vouch for them.
    streamed->begin(image, &poses, nullptr);
    int final_columns = 0;
    std::uniform_int_distribution<int> step(1, 400);
    for (;;) {
      const int next = final_columns + step(rng);
      if (next >= image.columns()) break;  // the last columns come with finish()
      final_columns = next;
      early += static_cast<std::uint64_t>(streamed->advance(image, &poses, final_columns));
    }
    EXPECT_FALSE(streamed->mapped()) << "the first blocks wait for the revolution's end";
    streamed->finish(image, &poses);
    EXPECT_TRUE(streamed->mapped());

    EXPECT_EQ(differing_cells(*whole, *streamed), 0u) << "revolution " << n;
    EXPECT_EQ(differing_cells(*whole, *stages), 0u) << "revolution " << n;
  }
  EXPECT_GT(known_cells(*whole), 20'000u);
  EXPECT_GT(early, 6u * 3u * 25u) << "most blocks are worked on before the revolution's end";
  // The shifted points went back to their own columns, none dropped.
  EXPECT_EQ(whole->counters().align.beyond_spread, 0u);
  EXPECT_EQ(streamed->counters().align.collisions, whole->counters().align.collisions);
  EXPECT_EQ(streamed->counters().features.measured, whole->counters().features.measured);
}

// A point farther from its firing's column than the image's azimuth spread
// says is dropped and counted, the same whole or in steps (else a block
// already smoothed could still change).
TEST(ObstacleStreaming, PointsBeyondTheAzimuthSpreadAreDroppedAndCounted) {
  const velodyne::RangeImageShape shape = kitti_shape();
  std::vector<float> buffer;
  velodyne::RangeImage scan(shape);
  ASSERT_TRUE(load_kitti_scan(test::shared_data("kitti/000000.bin"), buffer, scan));
  velodyne::RangeImage image = fired_like_an_hdl64e(scan, 20);
  image.azimuth_spread = 5 * 2.0 * std::numbers::pi / image.columns();  // claims less than the shifts
  auto whole = make_pipeline(shape);
  auto streamed = make_pipeline(shape);
  whole->process(image, nullptr, nullptr);
  streamed->begin(image, nullptr, nullptr);
  for (int c = 100; c < image.columns(); c += 100) streamed->advance(image, nullptr, c);
  streamed->finish(image, nullptr);
  EXPECT_GT(whole->counters().align.beyond_spread, 10'000u);
  EXPECT_EQ(streamed->counters().align.beyond_spread, whole->counters().align.beyond_spread);
  EXPECT_EQ(differing_cells(*whole, *streamed), 0u);
}

// The assembler in the loop: after every packet of a real HDL-32E capture the
// columns it calls final are taken (ObstaclePipeline::advance), as trailnavd's
// obstacle thread takes them from the lidar's progress word; each finished
// revolution is also mapped whole by a second pipeline.
class StreamingSink final : public velodyne::RevolutionSink {
 public:
  explicit StreamingSink(velodyne::RangeImageShape shape) : a_(shape), b_(shape) {}
  velodyne::RangeImage& next_image() noexcept override { return use_a_ ? a_ : b_; }
  void complete(velodyne::RangeImage& image) noexcept override {
    completed = &image;
    use_a_ = !use_a_;
  }
  velodyne::RangeImage* completed = nullptr;

 private:
  velodyne::RangeImage a_, b_;
  bool use_a_ = true;
};

void stream_capture(velodyne::Model model, const std::string& capture_file, int min_revolutions, std::size_t min_known) {
  SCOPED_TRACE(capture_file);
  auto decoder = velodyne::PacketDecoder::create(model, *velodyne::builtin_calibration(model));
  ASSERT_TRUE(decoder.decoder) << decoder.error;
  auto assembler_made = velodyne::RevolutionAssembler::create(*decoder.decoder, velodyne::AssemblerOptions{});
  ASSERT_TRUE(assembler_made.assembler) << assembler_made.error;
  velodyne::RevolutionAssembler& assembler = *assembler_made.assembler;
  StreamingSink sink(assembler.shape());
  auto whole = make_pipeline(assembler.shape());
  auto streamed = make_pipeline(assembler.shape());

  auto opened = capture::open_capture(test::shared_data(capture_file));
  ASSERT_TRUE(opened.reader) << opened.error;
  velodyne::SensorClock clock;
  std::uint32_t begun = 0;  // the generation the streamed pipeline began
  int revolutions = 0, compared = 0;
  std::uint64_t early = 0;
  while (auto d = opened.reader->next()) {
    if (d->payload.size() != velodyne::kDataPacketSize) continue;
    const std::uint32_t ts = velodyne::read_u32(d->payload.data() + velodyne::kTimestampOffset);
    // Raw files have no capture time: the packet clock stands for the host's.
    const std::int64_t host_ns = d->time_ns != 0 ? d->time_ns : static_cast<std::int64_t>(ts) * 1000;
    sink.completed = nullptr;
    assembler.add_packet(d->payload, clock.resolve(ts, host_ns), sink);
    if (sink.completed != nullptr) {
      ++revolutions;
      whole->process(*sink.completed, nullptr, nullptr);
      if (begun != 0) {
        streamed->finish(*sink.completed, nullptr);
        EXPECT_EQ(differing_cells(*whole, *streamed), 0u) << "revolution " << sink.completed->sequence;
        ++compared;
      } else {
        streamed->process(*sink.completed, nullptr, nullptr);  // not followed from its start
      }
      begun = 0;
    }
    const velodyne::RevolutionAssembler::Filling f = assembler.filling();
    if (f.image == nullptr || f.partial || f.final_columns <= 0) continue;
    if (begun != f.generation) {
      streamed->begin(*f.image, nullptr, nullptr);
      begun = f.generation;
    }
    early += static_cast<std::uint64_t>(streamed->advance(*f.image, nullptr, f.final_columns));
  }
  EXPECT_GE(revolutions, min_revolutions);
  EXPECT_GE(compared, revolutions - 1);
  EXPECT_GT(early, static_cast<std::uint64_t>(compared) * 20u);
  EXPECT_GT(known_cells(*whole), min_known);
  std::printf("%s: %d revolutions, %d compared, %llu blocks before their revolution's end, %zu known cells\n",
              capture_file.c_str(), revolutions, compared, static_cast<unsigned long long>(early), known_cells(*whole));
}

TEST(ObstacleStreaming, RealCapturesTakenPacketByPacketGiveTheWholeRevolutionsMaps) {
  stream_capture(velodyne::Model::hdl32e, "velodyne/mrpt_sample_velodyne_hdl32.pcap", 2, 5'000);
  stream_capture(velodyne::Model::vlp16, "velodyne/einride_vlp16_recording_raw1206.bin", 5, 800);
}

}  // namespace
}  // namespace trailnav::perception
