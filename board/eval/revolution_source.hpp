// Lidar revolutions from an offline input, deterministically: a bench
// recording (simulated or real; its lidar and position streams decoded and
// assembled exactly as the driver does) or a list of KITTI scans. A simulated
// recording also brings its ground truth. Shared by the offline tools
// (`trailnav obstacles`, `terrain-train`, `terrain-eval`).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "sim_truth.hpp"
#include "trailnav/drivers/cloud/cloud_image.hpp"
#include "trailnav/drivers/cloud/point_cloud.hpp"
#include "trailnav/drivers/velodyne/range_image.hpp"

namespace trailnav::eval {

// How point-cloud files (.bin, .pcd, .ply) become range images (drivers/cloud).
struct CloudInputOptions {
  // The lidar's ring layout: a preset name (cloud::ring_layout_preset) or a
  // layout file (.yaml, cloud::load_ring_layout);
  // empty: the HDL-64E for KITTI .bin scans, else needed. A calibration file
  // given to open() wins over the preset's elevations.
  std::string lidar;
  // Where a point's ring comes from; unset: the sensor's order for KITTI
  // .bin scans (they keep it and have no ring field), the file's ring field
  // or else the elevation for PCD and PLY.
  std::optional<cloud::RingSource> rings;
  int columns = 0;  // columns of a revolution; 0: the layout's (KITTI: 2160)
};

class RevolutionSource {
 public:
  struct Opened;
  // `inputs`: one recording directory or capture file, or point-cloud files
  // (KITTI .bin, PCD, PLY; each one revolution). `calibration`: empty (the
  // simulated scenario's or the model's default file), "builtin", or a
  // calibration file.
  static Opened open(const std::vector<std::string>& inputs, const std::string& calibration,
                     const CloudInputOptions& cloud_options = {});
  ~RevolutionSource();
  RevolutionSource(RevolutionSource&&) noexcept;

  // "recording", "kitti" (KITTI .bin scans), "cloud" (PCD or PLY files, or a mix)
  const std::string& input_kind() const noexcept { return kind_; }
  const std::string& model_name() const noexcept { return model_; }
  // The lidar model as velodyne::Model spells it ("HDL-64E" for KITTI scans).
  std::string_view lidar_model() const noexcept {
    return kind_ == "kitti" ? std::string_view("HDL-64E") : kind_ == "cloud" ? std::string_view(lidar_) : std::string_view(model_);
  }
  velodyne::RangeImageShape shape() const noexcept { return shape_; }
  // The simulated recording's truth, if it has one.
  const std::optional<SimTruth>& truth() const noexcept { return truth_; }
  // The lidar's position on the robot from the simulated scenario (zeros otherwise).
  std::array<double, 3> mount_translation() const noexcept;
  // The box around the sensor that is the recording vehicle itself
  // (features.self_box): KITTI's car; none for other inputs.
  std::optional<std::array<float, 6>> self_box() const noexcept;

  // Hands every revolution to `on_image` in order; stops early when it
  // returns false. `progress` gets the fraction read. Returns an error
  // message, or empty.
  std::string run(const std::function<bool(const velodyne::RangeImage&)>& on_image,
                  const std::function<void(double)>& progress = {});
  std::uint64_t malformed_packets() const noexcept { return malformed_; }

  // Point-cloud inputs, inside on_image: the file the revolution came from,
  // its points (in the file's order) and where each went in the range
  // image; null / empty for recordings.
  const cloud::PointCloud* scan_cloud() const noexcept;
  std::span<const cloud::PointPlace> scan_places() const noexcept;
  const std::string& scan_file() const noexcept;
  // Point-cloud inputs: each file's points by cell (cloud::CloudImager::
  // index()) instead of a range image, for a caller that takes them straight
  // from the cloud (ObstaclePipeline::align_scan); on_image then gets an
  // image that holds nothing, and scan_cells() the file's cells inside it.
  void take_scans_without_images(bool on) noexcept;
  const cloud::ScanCells* scan_cells() const noexcept;
  // Every file's counts summed.
  const cloud::CloudImageStats& cloud_totals() const noexcept;

 private:
  struct Impl;
  RevolutionSource();
  std::unique_ptr<Impl> impl_;
  std::string kind_, model_, lidar_;
  velodyne::RangeImageShape shape_{};
  std::optional<SimTruth> truth_;
  std::uint64_t malformed_ = 0;
};

struct RevolutionSource::Opened {
  std::optional<RevolutionSource> source;
  std::string error;
};

}  // namespace trailnav::eval
