#include "revolution_source.hpp"

#include <algorithm>
#include <filesystem>

#include "simulator.hpp"
#include "trailnav/drivers/recording/recording.hpp"
#include "trailnav/drivers/velodyne/calibration.hpp"
#include "trailnav/drivers/velodyne/decoder.hpp"
#include "trailnav/drivers/velodyne/packet.hpp"
#include "trailnav/drivers/velodyne/sensor_clock.hpp"
#include "trailnav/drivers/cloud/cloud_file.hpp"
#include "trailnav/runtime/config.hpp"
#include "trailnav/perception/kitti.hpp"

namespace trailnav::eval {

namespace fs = std::filesystem;
namespace vel = trailnav::velodyne;

namespace {

// Receives finished revolutions from the assembler and hands them on at once.
class ImmediateSink final : public vel::RevolutionSink {
 public:
  ImmediateSink(vel::RangeImageShape shape, const std::function<bool(const vel::RangeImage&)>& on_image)
      : a_(shape), b_(shape), on_image_(on_image) {}
  vel::RangeImage& next_image() noexcept override { return use_a_ ? a_ : b_; }
  void complete(vel::RangeImage& image) noexcept override {
    use_a_ = !use_a_;
    if (!stopped_) stopped_ = !on_image_(image);
  }
  bool stopped() const noexcept { return stopped_; }

 private:
  vel::RangeImage a_, b_;
  bool use_a_ = true;
  bool stopped_ = false;
  const std::function<bool(const vel::RangeImage&)>& on_image_;
};

std::optional<vel::Model> sniff_model(const std::string& input, int stream, std::string& error) {
  auto opened = recording::RecordingReader::open(input);
  if (!opened.reader) {
    error = opened.error;
    return std::nullopt;
  }
  while (auto e = opened.reader->next()) {
    if (e->stream != stream || e->payload.size() != vel::kDataPacketSize) continue;
    if (auto m = vel::detect_model(e->payload)) return m;
  }
  error = input + ": no lidar data packet names its model";
  return std::nullopt;
}

}  // namespace

struct RevolutionSource::Impl {
  std::vector<std::string> inputs;
  bool clouds = false;
  // Point-cloud files.
  std::optional<cloud::CloudImager> imager;
  cloud::PointCloud cloud;
  cloud::CloudScratch scratch;
  std::vector<cloud::PointPlace> places;
  bool without_images = false;
  std::optional<cloud::ScanCells> cells;  // without_images: the file's, inside on_image
  cloud::CloudImageStats stats, totals;
  std::string file;
  int lidar_stream = -1;
  int position_stream = -1;
  std::optional<vel::PacketDecoder> decoder;
  vel::AssemblerOptions assembler_options;
};

RevolutionSource::RevolutionSource() : impl_(std::make_unique<Impl>()) {}
RevolutionSource::~RevolutionSource() = default;
RevolutionSource::RevolutionSource(RevolutionSource&&) noexcept = default;

std::array<double, 3> RevolutionSource::mount_translation() const noexcept {
  if (!truth_) return {0.0, 0.0, 0.0};
  const auto& m = truth_->scenario.robot.lidar_mount;
  return {m.x(), m.y(), m.z()};
}

const cloud::PointCloud* RevolutionSource::scan_cloud() const noexcept {
  return impl_->clouds ? &impl_->cloud : nullptr;
}
std::span<const cloud::PointPlace> RevolutionSource::scan_places() const noexcept {
  if (!impl_->clouds) return {};
  return {impl_->places.data(), std::min(impl_->places.size(), impl_->cloud.size)};
}
const std::string& RevolutionSource::scan_file() const noexcept { return impl_->file; }
void RevolutionSource::take_scans_without_images(bool on) noexcept { impl_->without_images = on && impl_->clouds; }
const cloud::ScanCells* RevolutionSource::scan_cells() const noexcept {
  return impl_->cells ? &*impl_->cells : nullptr;
}
const cloud::CloudImageStats& RevolutionSource::cloud_totals() const noexcept { return impl_->totals; }

std::optional<std::array<float, 6>> RevolutionSource::self_box() const noexcept {
  if (kind_ == "kitti") return perception::kKittiCarBox;
  return std::nullopt;
}

RevolutionSource::Opened RevolutionSource::open(const std::vector<std::string>& inputs, const std::string& calibration,
                                                const CloudInputOptions& cloud_options) {
  if (inputs.empty()) {
    return {std::nullopt, "no input: give a recording directory, a pcap file, or point-cloud files (KITTI .bin, PCD, PLY)"};
  }
  const bool clouds = std::all_of(inputs.begin(), inputs.end(), [](const std::string& p) {
    return !fs::is_directory(p) && cloud::cloud_format_of(p).has_value();
  });
  if (!clouds && inputs.size() > 1) {
    return {std::nullopt, "give one recording or capture file, or only point-cloud files (.bin, .pcd, .ply)"};
  }
  RevolutionSource s;
  Impl& im = *s.impl_;
  im.inputs = inputs;
  im.clouds = clouds;
  if (!clouds && fs::is_directory(fs::path(inputs[0]) / "truth")) {
    auto loaded = load_sim_truth((fs::path(inputs[0]) / "truth").string());
    if (!loaded.truth) return {std::nullopt, loaded.error};
    s.truth_ = std::move(loaded.truth);
  }
  if (clouds) {
    const bool kitti = std::all_of(inputs.begin(), inputs.end(), [](const std::string& p) {
      return cloud::cloud_format_of(p) == cloud::CloudFormat::kitti_bin;
    });
    std::string lidar = cloud_options.lidar;
    if (lidar.empty() && kitti) lidar = "HDL-64E";
    std::string presets;
    for (const std::string& n : cloud::ring_layout_presets()) presets += (presets.empty() ? "" : ", ") + n;
    if (lidar.empty() && (calibration.empty() || calibration == "builtin")) {
      return {std::nullopt, "PCD and PLY files need the lidar's ring layout: give --lidar (a preset: " + presets +
                                "; or a layout file, docs/pointcloud.md) or --calibration FILE"};
    }
    std::optional<cloud::RingLayout> layout;
    const std::string ext = fs::path(lidar).extension().string();
    if (!lidar.empty()) {
      std::string error;
      layout = cloud::ring_layout_named(lidar, error);
      if (!layout) return {std::nullopt, error};
    }
    if (!calibration.empty() && calibration != "builtin") {
      auto c = vel::load_calibration(calibration);
      if (!c.calibration) return {std::nullopt, c.error};
      layout = cloud::ring_layout_from_calibration(*c.calibration, lidar.empty() ? calibration : lidar,
                                                   layout ? layout->columns : 2048);
    }
    if (kitti) layout->columns = perception::kKittiColumns;
    if (cloud_options.columns > 0) layout->columns = cloud_options.columns;
    cloud::CloudImageOptions copt;
    // KITTI's reflectance is 0..1; PCD and PLY writers give the sensor's 0..255 as it is.
    copt.intensity_scale = kitti ? 255.0f : 1.0f;
    copt.rings = cloud_options.rings.value_or(kitti ? cloud::RingSource::order : cloud::RingSource::automatic);
    im.imager.emplace(*layout, 2, copt);
    s.kind_ = kitti ? "kitti" : "cloud";
    s.lidar_ = lidar.empty() || ext == ".yaml" || ext == ".yml" ? layout->name : lidar;
    s.model_ = kitti ? "HDL-64E (KITTI)" : layout->name;
    s.shape_ = im.imager->shape();
    return {std::move(s), {}};
  }
  s.kind_ = "recording";
  auto opened = recording::RecordingReader::open(inputs[0]);
  if (!opened.reader) return {std::nullopt, opened.error};
  const auto& streams = opened.reader->streams();
  for (std::size_t i = 0; i < streams.size(); ++i) {
    if (streams[i].kind != recording::StreamKind::udp) continue;
    if (im.lidar_stream < 0 && (streams[i].name == "lidar" || streams[i].port == 2368)) im.lidar_stream = static_cast<int>(i);
    if (im.position_stream < 0 && (streams[i].name == "lidar-position" || streams[i].port == 8308)) {
      im.position_stream = static_cast<int>(i);
    }
  }
  if (im.lidar_stream < 0) return {std::nullopt, inputs[0] + ": no UDP stream named 'lidar' or on port 2368"};
  std::string error;
  const auto model = sniff_model(inputs[0], im.lidar_stream, error);
  if (!model) return {std::nullopt, error};
  s.model_ = std::string(vel::model_info(*model).name);
  std::string calib = calibration;
  if (calib.empty() && s.truth_) calib = s.truth_->scenario.lidar.calibration;
  if (calib.empty()) calib = sim::default_calibration_file(*model);
  std::optional<vel::Calibration> cal;
  if (!calib.empty() && calib != "builtin") {
    auto c = vel::load_calibration(calib);
    if (!c.calibration) return {std::nullopt, c.error};
    cal = std::move(c.calibration);
  } else {
    cal = vel::builtin_calibration(*model);
    if (!cal) return {std::nullopt, "the " + s.model_ + " needs its calibration: give --calibration FILE"};
  }
  vel::DecoderOptions dopt;
  dopt.selection = vel::ReturnSelection::strongest;
  auto created = vel::PacketDecoder::create(*model, *cal, dopt);
  if (!created.decoder) return {std::nullopt, created.error};
  im.decoder.emplace(std::move(*created.decoder));
  vel::AssemblerOptions aopt;
  if (s.truth_) aopt.rpm = s.truth_->scenario.lidar.rpm;
  auto made = vel::RevolutionAssembler::create(*im.decoder, aopt);
  if (!made.assembler) return {std::nullopt, made.error};
  im.assembler_options = aopt;
  s.shape_ = made.assembler->shape();
  return {std::move(s), {}};
}

std::string RevolutionSource::run(const std::function<bool(const vel::RangeImage&)>& on_image,
                                  const std::function<void(double)>& progress) {
  Impl& im = *impl_;
  if (im.clouds) {
    vel::RangeImage image(shape_);
    im.totals = {};
    for (std::size_t i = 0; i < im.inputs.size(); ++i) {
      im.file = im.inputs[i];
      if (Status st = cloud::load_cloud(im.file, im.cloud, im.scratch); !st) return st.message();
      if (im.places.size() < im.cloud.size) im.places.resize(im.cloud.capacity());
      if (im.without_images) {
        im.cells = im.imager->index(im.cloud, im.stats, im.places);
      } else {
        im.imager->fill(im.cloud, image, im.stats, im.places);
      }
      im.totals += im.stats;
      const bool more = on_image(image);
      im.cells.reset();
      if (!more) break;
      if (progress) progress(static_cast<double>(i + 1) / static_cast<double>(im.inputs.size()));
    }
    return {};
  }
  auto opened = recording::RecordingReader::open(im.inputs[0]);
  if (!opened.reader) return opened.error;
  recording::RecordingReader& reader = *opened.reader;
  // Every run starts a fresh assembler (runs are independent and repeatable).
  auto made = vel::RevolutionAssembler::create(*im.decoder, im.assembler_options);
  if (!made.assembler) return made.error;
  vel::RevolutionAssembler& assembler = *made.assembler;
  ImmediateSink sink(shape_, on_image);
  vel::SensorClock clock;
  std::uint64_t events = 0;
  while (auto e = reader.next()) {
    if (e->stream == im.position_stream && e->payload.size() == vel::kPositionPacketSize) {
      vel::PositionPacket pp;
      if (vel::decode_position_packet(e->payload, pp) == vel::PositionError::none) clock.on_position_packet(pp);
    } else if (e->stream == im.lidar_stream && e->payload.size() == vel::kDataPacketSize) {
      const std::int64_t t = clock.resolve(vel::read_u32(e->payload.data() + vel::kTimestampOffset), e->time_ns);
      if (assembler.add_packet(e->payload, t, sink) != vel::PacketError::none) ++malformed_;
    } else if (e->stream == im.lidar_stream) {
      ++malformed_;
    }
    if (progress && ++events % 512 == 0) {
      progress(static_cast<double>(reader.position()) / static_cast<double>(std::max<std::uint64_t>(reader.size(), 1)));
    }
    if (sink.stopped()) break;
  }
  if (progress) progress(1.0);
  return {};
}

}  // namespace trailnav::eval
