// One lidar revolution as a range image, and the assembler that builds it
// packet by packet.
//
// Rows are rings (laser index sorted by elevation, 0 = lowest); columns are
// azimuth bins of equal width, one per firing of the sensor at its current
// rotation rate, counted from the cut azimuth clockwise as the sensor turns.
// A firing goes to the column of its firing azimuth (before the laser's own
// rotation correction), so the lasers of one firing share a column; each
// cell keeps the point's own azimuth. Dual-return data fills two layers:
// layer 0 the strongest return, layer 1 the last (identical returns are in
// both); an image of one layer keeps the strongest.
//
// Every column is either `received` (a packet covered its azimuth: a cell
// without a return there means the laser saw nothing) or `missing` (no packet
// covered it: a lost packet, or the start of the stream). Consumers must not
// read a missing column as free space.
#pragma once

#include <cstdint>
#include <array>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "trailnav/drivers/velodyne/decoder.hpp"
#include "trailnav/drivers/velodyne/revolution_cut.hpp"
#include "trailnav/runtime/mailbox.hpp"

namespace trailnav::velodyne {

struct RangeCell {
  float x = 0.0f;  // m, sensor frame (x forward, y left, z up)
  float y = 0.0f;
  float z = 0.0f;
  float distance = 0.0f;   // m; 0: no return in this cell
  float azimuth = 0.0f;    // rad, the laser's pointing direction
  float time = 0.0f;       // s after the revolution's first firing
  float intensity = 0.0f;  // 0..255
  ReturnKind kind = ReturnKind::strongest;

  bool valid() const noexcept { return distance > 0.0f; }
};

enum class ColumnState : std::uint8_t { missing = 0, received = 1 };

struct RangeImageShape {
  int rings = 0;
  int max_columns = 0;  // capacity: columns at the slowest rotation configured
  int layers = 1;       // 2 for dual returns
};

class RangeImage {
 public:
  explicit RangeImage(RangeImageShape shape);

  const RangeImageShape& shape() const noexcept { return shape_; }
  int rings() const noexcept { return shape_.rings; }
  int layers() const noexcept { return shape_.layers; }
  int columns() const noexcept { return columns_; }  // in use for this revolution

  const RangeCell& at(int layer, int ring, int column) const noexcept { return cells_[index(layer, ring, column)]; }
  RangeCell& at(int layer, int ring, int column) noexcept { return cells_[index(layer, ring, column)]; }
  // One ring of one layer, columns() cells.
  std::span<const RangeCell> row(int layer, int ring) const noexcept {
    return {cells_.data() + index(layer, ring, 0), static_cast<std::size_t>(columns_)};
  }
  ColumnState column_state(int column) const noexcept { return column_state_[static_cast<std::size_t>(column)]; }
  // When the firing of a received column took place (the sensor's clock, as
  // start_ns): set by whoever fills the column, else by finish() from the
  // column's place between start_ns and end_ns. A reader of a revolution in
  // progress (trailnavd's obstacle thread) finds it set for every column the
  // assembler has passed.
  static constexpr std::int64_t kNoTime = INT64_MIN;  // column_time_ns() of a column not received
  std::int64_t column_time_ns(int column) const noexcept { return column_time_[static_cast<std::size_t>(column)]; }
  void set_column_time(int first_column, int end_column, std::int64_t time_ns) noexcept;  // [first, end)
  double column_azimuth(int column) const noexcept;  // rad, centre of the bin (firing azimuth)

  // Revolution metadata.
  std::uint64_t sequence = 0;   // revolution number since the assembler started (first complete: 1)
  std::int64_t start_ns = 0;    // time of the first firing
  std::int64_t end_ns = 0;      // time of the last firing
  // How far (rad) a point's own azimuth may lie from its column's bin: the
  // lasers' rotation corrections and a firing's own sweep (RangeCell::azimuth).
  // Whoever fills the image sets it (the assembler from the calibration).
  double azimuth_spread = 0.0;
  double rpm = 0.0;             // rotation rate measured over this revolution
  double cut_azimuth = 0.0;     // rad
  int points = 0;               // valid cells over all layers
  int missing_columns = 0;
  std::uint32_t packets = 0;       // data packets that contributed
  std::uint32_t lost_packets = 0;  // packets inferred lost inside this revolution
  std::uint32_t collisions = 0;    // firings dropped because their column already had one
  // Host receive time (host time, runtime/host_clock.hpp) of the packet that completed this
  // revolution, set by the driver task (0 offline): where latency is measured from.
  std::int64_t completed_receive_ns = 0;
  // trailnavd's reference clock (host time) minus the sensor's
  // clock that start_ns and end_ns are on, when the revolution was published
  // (runtime/clock_relation.hpp; 0 offline). The times above stay on the
  // sensor's clock so that a recording always gives the same revolutions;
  // whatever relates them to poses or stamps them for others adds this.
  std::int64_t clock_offset_ns = 0;
  std::int64_t reference_start_ns() const noexcept { return start_ns + clock_offset_ns; }
  std::int64_t reference_end_ns() const noexcept { return end_ns + clock_offset_ns; }

  // Clears the first `columns` columns (no allocation).
  void reset(int columns) noexcept;
  // reset() without clearing the cells: the assembler clears each column
  // right before its first write (clear_columns()) and the rest when the
  // revolution ends, in the cache lines it writes anyway, instead of sweeping
  // the whole image (4 MB for an HDL-64E) in one run of the lidar task.
  void begin(int columns) noexcept;
  void clear_columns(int first_column, int end_column) noexcept;  // [first, end) of every ring and layer
  void mark_received(int first_column, int end_column) noexcept;  // [first, end)
  void finish() noexcept;  // counts the missing columns, gives received columns without a time theirs

 private:
  std::size_t index(int layer, int ring, int column) const noexcept {
    return (static_cast<std::size_t>(layer) * static_cast<std::size_t>(shape_.rings) + static_cast<std::size_t>(ring)) *
               static_cast<std::size_t>(shape_.max_columns) +
           static_cast<std::size_t>(column);
  }

  RangeImageShape shape_;
  int columns_ = 0;
  std::vector<RangeCell> cells_;
  std::vector<ColumnState> column_state_;
  std::vector<std::int64_t> column_time_;  // kNoTime: not set this revolution
};

// The progress word a driver stores (Broadcast::progress()) for a revolution
// it is filling, for a reader that follows it: which one (the assembler's
// generation) and how many of its columns no longer change.
constexpr std::uint64_t revolution_progress(std::uint32_t generation, int final_columns) noexcept {
  return (static_cast<std::uint64_t>(generation) << 32) | static_cast<std::uint32_t>(final_columns);
}
constexpr std::uint32_t progress_generation(std::uint64_t word) noexcept { return static_cast<std::uint32_t>(word >> 32); }
constexpr int progress_columns(std::uint64_t word) noexcept { return static_cast<int>(word & 0xffffffffu); }

// Where finished revolutions go. The assembler writes into next_image() and
// hands it back through complete(); the two calls alternate.
class RevolutionSink {
 public:
  virtual ~RevolutionSink() = default;
  virtual RangeImage& next_image() noexcept = 0;
  virtual void complete(RangeImage& image) noexcept = 0;
  // The revolution in `image` is dropped and starts anew (a jump in the
  // sensor's clock): where to fill it. Someone may be reading the old one
  // while it arrives (trailnavd), so a sink that lets them gives a fresh image.
  virtual RangeImage& restart_image(RangeImage& image) noexcept { return image; }
};

// Publishes every revolution as one snapshot through a Mailbox.
class MailboxRevolutionSink final : public RevolutionSink {
 public:
  explicit MailboxRevolutionSink(Mailbox<RangeImage>& mailbox) noexcept : mailbox_(mailbox) {}
  RangeImage& next_image() noexcept override { return mailbox_.write_slot(); }
  void complete(RangeImage&) noexcept override { mailbox_.publish(); }

 private:
  Mailbox<RangeImage>& mailbox_;
};

struct AssemblerOptions {
  double cut_azimuth_rad = 0.0;
  double rpm = 600.0;      // expected rotation rate: the initial column count
  double min_rpm = 300.0;  // slowest rate to hold: sets the capacity
  bool follow_rpm = true;  // size each revolution's columns for the rate measured over the last one
  bool dual_returns = false;  // two layers: strongest and last (decoder selection `all`)
};

struct AssemblerCounters {
  std::uint64_t packets = 0;
  std::uint64_t malformed = 0;      // rejected by the decoder
  std::uint64_t out_of_order = 0;   // timestamp not after the previous packet's: dropped
  // The packet clock jumped by more than half a revolution either way (the
  // sensor fell silent, or its clock stepped): the revolution in progress is
  // dropped, never joined across the jump, and a new one starts.
  std::uint64_t discontinuities = 0;
  std::uint64_t lost_packets = 0;   // inferred from gaps in packet time and azimuth
  std::uint64_t revolutions = 0;    // completed and handed to the sink
  std::uint64_t partial_revolutions = 0;  // the first, incomplete one (not handed on)
  std::uint64_t rpm_changes = 0;
  std::uint64_t collisions = 0;
};

class RevolutionAssembler {
 public:
  struct Created;
  static Created create(const PacketDecoder& decoder, const AssemblerOptions& options);
  // What create() would refuse, as a message; empty when the options are fine.
  static std::string check_options(const AssemblerOptions& options);
  // The shape of the images an assembler with these options fills.
  static RangeImageShape shape_for(const ModelInfo& model, const AssemblerOptions& options) noexcept;

  // The shape every image handed to this assembler must have.
  const RangeImageShape& shape() const noexcept { return shape_; }
  int columns_for_rpm(double rpm) const noexcept;
  int columns() const noexcept { return columns_; }

  // Decodes one data packet. `packet_time_ns` is the absolute time of its
  // first firing (see SensorClock). Completed revolutions go to `sink`.
  // Returns the decoder's verdict; a rejected packet changes nothing.
  PacketError add_packet(std::span<const std::uint8_t> payload, std::int64_t packet_time_ns, RevolutionSink& sink) noexcept;
  // The time of the newest firing placed so far (sensor clock).
  std::int64_t last_firing_ns() const noexcept { return last_firing_ns_; }
  // The part of a turn from the newest firing to the cut, in (0, 1]: the
  // revolution in progress ends that far ahead, at rpm(). Negative before
  // the first packet.
  double turn_to_cut() const noexcept;
  double rpm() const noexcept { return current_rpm_; }
  // The revolution being filled, for a reader that follows it: its image
  // (null before the first packet), a number that changes each time a
  // revolution begins in it, how many of its columns no longer change (the
  // firings arrive in column order: those before the newest firing's), and
  // whether it began mid-turn (the first one: it is not published).
  struct Filling {
    const RangeImage* image = nullptr;
    std::uint32_t generation = 0;
    int final_columns = 0;
    bool partial = true;
  };
  Filling filling() const noexcept { return {image_, generation_, previous_column_ + 1, partial_}; }
  std::uint32_t generation() const noexcept { return generation_; }

  const AssemblerCounters& counters() const noexcept { return counters_; }

 private:
  RevolutionAssembler(const PacketDecoder& decoder, const AssemblerOptions& options);

  void start_revolution(RevolutionSink& sink, std::int64_t first_ns, bool partial) noexcept;
  void finish_revolution(RevolutionSink& sink, std::int64_t next_start_ns, bool continuous) noexcept;
  // Columns of the sequences [begin, end) of the current packet in image_.
  void clear_through_previous_column() noexcept;
  void assign_columns(const PacketInfo& info, std::int64_t packet_time_ns, int begin, int end, bool continuous) noexcept;
  void place_points(const PacketInfo& info, int begin, int end, std::int64_t packet_time_ns) noexcept;

  const PacketDecoder* decoder_;
  AssemblerOptions options_;
  RangeImageShape shape_;
  double firings_per_second_ = 0.0;
  double max_rotation_correction_ = 0.0;  // rad, over the calibration's lasers
  double current_rpm_ = 0.0;
  int columns_ = 0;
  double rate_azimuth_ = 0.0;  // hundredths of a degree turned since the revolution began
  double rate_time_us_ = 0.0;  // over this much packet time
  float previous_first_relative_ = 0.0f;
  RevolutionCut cut_;
  std::vector<Point> points_;

  RangeImage* image_ = nullptr;  // being filled; nullptr before the first packet
  bool partial_ = true;          // image_ started mid-turn (the first one)
  std::int64_t last_firing_ns_ = 0;
  std::array<int, kMaxSequencesPerPacket> column_{};  // per sequence of the current packet; -1: dropped (column taken)
  // The previous packet.
  bool have_previous_ = false;
  std::uint32_t previous_timestamp_us_ = 0;
  int previous_column_ = -1;         // of its last sequence, in image_
  int cleared_ = 0;                  // image_'s columns below this were cleared this revolution (RangeImage::begin)
  std::uint32_t generation_ = 0;     // revolutions begun
  AssemblerCounters counters_;
};

struct RevolutionAssembler::Created {
  std::optional<RevolutionAssembler> assembler;
  std::string error;
};

}  // namespace trailnav::velodyne
