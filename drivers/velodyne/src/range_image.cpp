#include "trailnav/drivers/velodyne/range_image.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace trailnav::velodyne {
namespace {

constexpr float kTurn = 36000.0f;  // hundredths of a degree
float wrap_turn(float hundredths) noexcept {
  if (hundredths < 0.0f) hundredths += kTurn;
  if (hundredths >= kTurn) hundredths -= kTurn;
  return hundredths;
}

}  // namespace

RangeImage::RangeImage(RangeImageShape shape)
    : shape_(shape),
      cells_(static_cast<std::size_t>(shape.layers) * static_cast<std::size_t>(shape.rings) *
             static_cast<std::size_t>(shape.max_columns)),
      column_state_(static_cast<std::size_t>(shape.max_columns), ColumnState::missing),
      column_time_(static_cast<std::size_t>(shape.max_columns), kNoTime) {}

double RangeImage::column_azimuth(int column) const noexcept {
  const double width = 2.0 * std::numbers::pi / static_cast<double>(columns_);
  double a = cut_azimuth + (static_cast<double>(column) + 0.5) * width;
  if (a >= 2.0 * std::numbers::pi) a -= 2.0 * std::numbers::pi;
  return a;
}

void RangeImage::reset(int columns) noexcept {
  begin(columns);
  clear_columns(0, columns_);
}

void RangeImage::clear_columns(int first_column, int end_column) noexcept {
  first_column = std::max(first_column, 0);
  end_column = std::min(end_column, columns_);
  if (first_column >= end_column) return;
  for (int layer = 0; layer < shape_.layers; ++layer) {
    for (int ring = 0; ring < shape_.rings; ++ring) {
      RangeCell* row_cells = cells_.data() + index(layer, ring, 0);
      std::fill(row_cells + first_column, row_cells + end_column, RangeCell{});
    }
  }
}

void RangeImage::begin(int columns) noexcept {
  columns_ = std::clamp(columns, 1, shape_.max_columns);
  std::fill(column_state_.begin(), column_state_.begin() + columns_, ColumnState::missing);
  std::fill(column_time_.begin(), column_time_.begin() + columns_, kNoTime);
  sequence = 0;
  start_ns = end_ns = 0;
  rpm = 0.0;
  points = missing_columns = 0;
  packets = lost_packets = collisions = 0;
}

void RangeImage::mark_received(int first_column, int end_column) noexcept {
  first_column = std::max(first_column, 0);
  end_column = std::min(end_column, columns_);
  for (int c = first_column; c < end_column; ++c) column_state_[static_cast<std::size_t>(c)] = ColumnState::received;
}

void RangeImage::set_column_time(int first_column, int end_column, std::int64_t time_ns) noexcept {
  first_column = std::max(first_column, 0);
  end_column = std::min(end_column, columns_);
  for (int c = first_column; c < end_column; ++c) column_time_[static_cast<std::size_t>(c)] = time_ns;
}

void RangeImage::finish() noexcept {
  missing_columns = static_cast<int>(
      std::count(column_state_.begin(), column_state_.begin() + columns_, ColumnState::missing));
  const double span = static_cast<double>(end_ns - start_ns);
  for (int c = 0; c < columns_; ++c) {
    auto& t = column_time_[static_cast<std::size_t>(c)];
    if (t == kNoTime && column_state_[static_cast<std::size_t>(c)] == ColumnState::received) {
      t = start_ns + static_cast<std::int64_t>(span * (c + 0.5) / columns_);
    }
  }
}

namespace {

double firings_per_second(const ModelInfo& m) noexcept { return m.sequences_per_block * 1e6 / m.group_period_us; }

}  // namespace

std::string RevolutionAssembler::check_options(const AssemblerOptions& options) {
  if (!(options.min_rpm >= 60.0 && options.min_rpm <= 1200.0)) {
    return "min_rpm " + std::to_string(options.min_rpm) + " is outside 60..1200";
  }
  if (!(options.rpm >= options.min_rpm && options.rpm <= 1500.0)) {
    return "rpm " + std::to_string(options.rpm) + " must lie between min_rpm (" + std::to_string(options.min_rpm) +
           ") and 1500";
  }
  if (!(options.cut_azimuth_rad >= 0.0 && options.cut_azimuth_rad < 2.0 * std::numbers::pi)) {
    return "the cut azimuth must lie in [0, 360) degrees";
  }
  return "";
}

RangeImageShape RevolutionAssembler::shape_for(const ModelInfo& model, const AssemblerOptions& options) noexcept {
  RangeImageShape shape;
  shape.rings = model.lasers;
  shape.max_columns = static_cast<int>(std::lround(firings_per_second(model) * 60.0 / options.min_rpm));
  shape.layers = options.dual_returns ? 2 : 1;
  return shape;
}

RevolutionAssembler::Created RevolutionAssembler::create(const PacketDecoder& decoder, const AssemblerOptions& options) {
  Created result;
  result.error = check_options(options);
  if (result.error.empty()) result.assembler.emplace(RevolutionAssembler(decoder, options));
  return result;
}

RevolutionAssembler::RevolutionAssembler(const PacketDecoder& decoder, const AssemblerOptions& options)
    : decoder_(&decoder),
      options_(options),
      shape_(shape_for(decoder.model(), options)),
      firings_per_second_(firings_per_second(decoder.model())),
      current_rpm_(options.rpm),
      cut_(options.cut_azimuth_rad),
      points_(kMaxPointsPerPacket) {
  columns_ = columns_for_rpm(options.rpm);
  for (const LaserCorrection& l : decoder.calibration().lasers) {
    max_rotation_correction_ = std::max(max_rotation_correction_, std::abs(l.rot_correction));
  }
}

double RevolutionAssembler::turn_to_cut() const noexcept {
  const float after_cut = cut_.last_relative();
  if (after_cut < 0.0f) return -1.0;
  return static_cast<double>(kTurn - after_cut) / static_cast<double>(kTurn);
}

int RevolutionAssembler::columns_for_rpm(double rpm) const noexcept {
  const auto c = static_cast<int>(std::lround(firings_per_second_ * 60.0 / rpm));
  return std::clamp(c, 1, shape_.max_columns);
}

PacketError RevolutionAssembler::add_packet(std::span<const std::uint8_t> payload, std::int64_t packet_time_ns,
                                            RevolutionSink& sink) noexcept {
  const PacketInfo info = decoder_->decode(payload, points_);
  if (info.error != PacketError::none) {
    ++counters_.malformed;
    return info.error;
  }
  const int n = info.sequences;
  const ModelInfo& m = decoder_->model();

  // Order and loss, from the packet clock and from the azimuth.
  std::int64_t lost = 0;
  bool restart = false;
  const std::int64_t dt = have_previous_ ? hour_clock_delta_us(info.timestamp_us, previous_timestamp_us_) : 0;
  if (have_previous_ && static_cast<double>(std::abs(dt)) > 30e6 / current_rpm_) {
    // A jump of over half a revolution: points from both sides of it in one
    // revolution would be placed with poses seconds apart.
    ++counters_.discontinuities;
    restart = true;
    have_previous_ = false;
    rate_azimuth_ = 0.0;
    rate_time_us_ = 0.0;
    if (image_ != nullptr && !partial_) ++counters_.partial_revolutions;
  }
  if (have_previous_) {
    if (dt <= 0) {
      ++counters_.out_of_order;
      return PacketError::none;
    }
    const double packet_us = static_cast<double>(n) / m.sequences_per_block * m.group_period_us;
    if (static_cast<double>(dt) > 1.5 * packet_us) {
      lost = std::llround(static_cast<double>(dt) / packet_us) - 1;
    }
  }
  const int first_new = cut_.first_new_sequence(info);  // n: the packet does not cross the cut
  if (have_previous_ && n > 1) {
    const float advance = wrap_turn(cut_.relative(n - 1) - cut_.relative(0)) / static_cast<float>(n - 1);
    const float gap = wrap_turn(cut_.relative(0) - cut_.previous_relative());
    if (advance > 0.0f && gap > (static_cast<float>(n) * 0.5f + 1.0f) * advance && gap < kTurn / 2) {
      lost = std::max<std::int64_t>(lost, std::lround((gap / advance - 1.0f) / static_cast<float>(n)));
    }
  }
  ++counters_.packets;
  counters_.lost_packets += static_cast<std::uint64_t>(lost);
  if (have_previous_) {
    // Rotation rate: azimuth advance over packet time since the last revolution began.
    rate_azimuth_ += static_cast<double>(wrap_turn(cut_.relative(0) - previous_first_relative_));
    rate_time_us_ += static_cast<double>(dt);
  }
  previous_first_relative_ = cut_.relative(0);

  const auto sequence_ns = [&](int s) {
    return packet_time_ns + std::llround(static_cast<double>(info.sequence_time_us[static_cast<std::size_t>(s)]) * 1e3);
  };
  if (image_ == nullptr || restart) start_revolution(sink, sequence_ns(0), true);
  if (lost > 0) image_->lost_packets += static_cast<std::uint32_t>(std::min<std::int64_t>(lost, 0xFFFFFFFF));

  const bool continuous = have_previous_ && lost == 0;
  if (first_new > 0) {
    ++image_->packets;
    assign_columns(info, packet_time_ns, 0, first_new, continuous);
    clear_through_previous_column();
    place_points(info, 0, first_new, packet_time_ns);
  }
  if (first_new < n) {
    finish_revolution(sink, sequence_ns(first_new), first_new > 0 || continuous);
    start_revolution(sink, sequence_ns(first_new), false);
    ++image_->packets;
    assign_columns(info, packet_time_ns, first_new, n, first_new > 0 || continuous);
    clear_through_previous_column();
    place_points(info, first_new, n, packet_time_ns);
  }

  have_previous_ = true;
  previous_timestamp_us_ = info.timestamp_us;
  return PacketError::none;
}

void RevolutionAssembler::clear_through_previous_column() noexcept {
  // The columns placed into are assigned in increasing order (a firing
  // whose column lies behind the last one is dropped), so each is cleared
  // once, just before its first points land there.
  if (previous_column_ < cleared_) return;
  image_->clear_columns(cleared_, previous_column_ + 1);
  cleared_ = previous_column_ + 1;
}

void RevolutionAssembler::assign_columns(const PacketInfo& info, std::int64_t packet_time_ns, int begin, int end,
                                         bool continuous) noexcept {
  RangeImage& image = *image_;
  const int columns = image.columns();
  const float scale = static_cast<float>(columns) / kTurn;
  // Each column covered takes the time of the firing that covered it; only
  // columns past the newest firing's are covered (those behind it no longer
  // change: trailnavd's obstacle thread may have read them already).
  const auto receive = [&](int first, int last, std::int64_t time_ns) {
    image.mark_received(first, last);
    image.set_column_time(first, last, time_ns);
  };
  for (int s = begin; s < end; ++s) {
    const std::int64_t time_ns =
        packet_time_ns + std::llround(static_cast<double>(info.sequence_time_us[static_cast<std::size_t>(s)]) * 1e3);
    const float position = cut_.relative(s) * scale;
    int c = std::min(static_cast<int>(position), columns - 1);
    // Coverage: everything since the previous firing when nothing was lost
    // in between, else only this firing's own column.
    const bool joined = s > begin || continuous;
    if (joined && previous_column_ >= 0) {
      receive(previous_column_ + 1, c + 1, time_ns);
    } else if (joined && previous_column_ < 0) {
      receive(0, c + 1, time_ns);  // first firing after the cut
    }
    // The columns up to the newest firing's are final (a reader may be
    // working on them: trailnavd's obstacle thread): a firing behind it marks nothing.
    if (c > previous_column_) receive(c, c + 1, time_ns);
    // Two firings in one bin (the bins are one firing wide, but azimuth
    // jitters): the later one moves one bin on when that one is free.
    if (c <= previous_column_) {
      if (previous_column_ == c && c + 1 < columns) {
        c += 1;
        receive(c, c + 1, time_ns);
      } else {
        column_[static_cast<std::size_t>(s)] = -1;
        ++image.collisions;
        ++counters_.collisions;
        continue;
      }
    }
    column_[static_cast<std::size_t>(s)] = c;
    previous_column_ = c;
  }
}

void RevolutionAssembler::place_points(const PacketInfo& info, int begin, int end, std::int64_t packet_time_ns) noexcept {
  RangeImage& image = *image_;
  const bool two_layers = image.layers() == 2;
  const double since_start_s = static_cast<double>(packet_time_ns - image.start_ns) * 1e-9;
  for (int i = 0; i < info.points; ++i) {
    const Point& p = points_[static_cast<std::size_t>(i)];
    if (p.sequence < begin || p.sequence >= end) continue;
    const int c = column_[p.sequence];
    if (c < 0) continue;
    if (!two_layers && p.kind == ReturnKind::dual_last) continue;  // one layer: the strongest return
    RangeCell cell;
    cell.x = p.x;
    cell.y = p.y;
    cell.z = p.z;
    cell.distance = p.distance;
    cell.azimuth = p.azimuth;
    cell.time = static_cast<float>(since_start_s + static_cast<double>(p.time));
    cell.intensity = p.intensity;
    cell.kind = p.kind;
    const int layer = two_layers && p.kind == ReturnKind::dual_last ? 1 : 0;
    const int valid = cell.valid() ? 1 : 0;  // each cell is written once per revolution
    image.at(layer, p.ring, c) = cell;
    image.points += valid;
    if (two_layers && p.kind == ReturnKind::dual_both) {
      image.at(1, p.ring, c) = cell;
      image.points += valid;
    }
  }
  const std::int64_t last_ns =
      packet_time_ns + std::llround(static_cast<double>(info.sequence_time_us[static_cast<std::size_t>(end - 1)]) * 1e3);
  last_firing_ns_ = std::max(last_firing_ns_, last_ns);
}

void RevolutionAssembler::start_revolution(RevolutionSink& sink, std::int64_t first_ns, bool partial) noexcept {
  // Columns for the rate measured over the last revolution (or the part of
  // one seen at start-up), when it differs from the current one by over 2 %.
  if (options_.follow_rpm && rate_time_us_ > 20'000.0 && rate_azimuth_ > 0.0) {
    const double measured = rate_azimuth_ / static_cast<double>(kTurn) / rate_time_us_ * 60e6;
    if (std::abs(measured - current_rpm_) > 0.02 * current_rpm_) {
      const int columns = columns_for_rpm(measured);
      if (columns != columns_) ++counters_.rpm_changes;
      current_rpm_ = measured;
      columns_ = columns;
    }
  }
  rate_azimuth_ = 0.0;
  rate_time_us_ = 0.0;
  if (image_ == nullptr) {
    image_ = &sink.next_image();
  } else if (!partial_) {
    image_ = &sink.restart_image(*image_);  // a full revolution dropped (a restart): a reader may follow it
  }
  ++generation_;
  image_->begin(columns_);
  image_->azimuth_spread = max_rotation_correction_ + 2.0 * 2.0 * std::numbers::pi / static_cast<double>(columns_);
  cleared_ = 0;
  image_->start_ns = first_ns;
  image_->cut_azimuth = options_.cut_azimuth_rad;
  partial_ = partial;
  previous_column_ = -1;
  last_firing_ns_ = first_ns;
}

void RevolutionAssembler::finish_revolution(RevolutionSink& sink, std::int64_t next_start_ns, bool continuous) noexcept {
  RangeImage& image = *image_;
  // The firings up to the cut were seen when nothing was lost before it.
  if (continuous && previous_column_ >= 0) {
    image.mark_received(previous_column_ + 1, image.columns());
    image.set_column_time(previous_column_ + 1, image.columns(), last_firing_ns_);
  }
  image.clear_columns(cleared_, image.columns());  // the columns no firing was placed in
  cleared_ = image.columns();
  image.end_ns = last_firing_ns_;
  image.finish();
  if (partial_) {
    ++counters_.partial_revolutions;
    return;  // the same image is reused for the first full revolution
  }
  const std::int64_t duration = next_start_ns - image.start_ns;
  image.rpm = duration > 0 ? 60e9 / static_cast<double>(duration) : 0.0;
  image.sequence = ++counters_.revolutions;
  sink.complete(image);  // the image is the sink's from here on
  image_ = nullptr;
}

}  // namespace trailnav::velodyne
