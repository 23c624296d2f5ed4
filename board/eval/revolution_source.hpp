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
#include <string>
#include <vector>

#include "sim_truth.hpp"
#include "trailnav/drivers/velodyne/range_image.hpp"

namespace trailnav::eval {

class RevolutionSource {
 public:
  struct Opened;
  // `inputs`: one recording directory or capture file, or KITTI .bin files.
  // `calibration`: empty (the simulated scenario's or the model's default
  // file), "builtin", or a calibration file.
  static Opened open(const std::vector<std::string>& inputs, const std::string& calibration);
  ~RevolutionSource();
  RevolutionSource(RevolutionSource&&) noexcept;

  const std::string& input_kind() const noexcept { return kind_; }    // "recording", "kitti"
  const std::string& model_name() const noexcept { return model_; }
  // The lidar model as velodyne::Model spells it ("HDL-64E" for KITTI scans).
  std::string_view lidar_model() const noexcept {
    return kind_ == "kitti" ? std::string_view("HDL-64E") : std::string_view(model_);
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

 private:
  struct Impl;
  RevolutionSource();
  std::unique_ptr<Impl> impl_;
  std::string kind_, model_;
  velodyne::RangeImageShape shape_{};
  std::optional<SimTruth> truth_;
  std::uint64_t malformed_ = 0;
};

struct RevolutionSource::Opened {
  std::optional<RevolutionSource> source;
  std::string error;
};

}  // namespace trailnav::eval
