// The traversability layer on the robot (thesis §6.3) and its demonstration
// mode, in two halves that meet only through mailboxes:
//
//   terrain thread (real time)                 training thread (normal scheduling)
//   TravOnline: the mapper's sums sink ──────► TravTrainer: each finished local map
//     layer: P(trav) into the class map          trained in (§6.3.4: χ² test, merge),
//     recorder: footprint cells, words   ◄────── the models handed back to the layer,
//                                                 the model file saved atomically
//
// Neither half waits for the other nor touches the heap after construction:
// a finished local map's word counts go by Mailbox<LocalMapWords> (should
// the trainer ever fall a whole local map behind, the older one is counted
// as lost), the newer models by Mailbox<TravModels>, and the file is
// serialised into a buffer sized for the largest model and written with
// AtomicFile.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "trailnav/perception/terrain_mapper.hpp"
#include "trailnav/perception/trav_layer.hpp"
#include "trailnav/perception/trav_learner.hpp"
#include "trailnav/perception/trav_recorder.hpp"
#include "trailnav/runtime/atomic_file.hpp"
#include "trailnav/runtime/mailbox.hpp"
#include "trailnav/runtime/scheduler.hpp"
#include "trailnav/runtime/status_board.hpp"

namespace trailnav::perception::trav {

// A finished local map's words by label, on its way to the trainer.
struct LocalMapWords {
  explicit LocalMapWords(std::uint32_t vocabulary) : counts(vocabulary) {}
  WordCounts counts;
};

struct OnlineCounters {
  LayerCounters layer;
  RecorderCounters recorder;
  std::uint64_t handed = 0;         // local maps handed to the trainer
  std::uint64_t model_updates = 0;  // newer models the layer took
  std::uint32_t models = 0;         // terrain models the layer classifies with
};

// The terrain thread's half: set as the TerrainMapper's sums sink.
class TravOnline final : public CellSumsSink {
 public:
  // Without a recorder (and its two mailboxes) the layer only classifies.
  // With one over the layer's vocabulary, each cell's ground and word are
  // worked out once, by the layer, and recorded as they are.
  explicit TravOnline(TravLayer& layer, TravRecorder* recorder = nullptr, Mailbox<LocalMapWords>* local_maps = nullptr,
                      Mailbox<TravModels>* models_in = nullptr) noexcept;

  void cell_sums(CellIndex cell, const CellStats& sums, const FeatureVector* feature, double x,
                 double y) noexcept override;
  void robot_pose(double x, double y, double yaw, std::int64_t time_ns) noexcept override;
  void step_begins(double robot_x, double robot_y, std::int64_t now_ns, TerrainClassMap& map) noexcept override;

  // trailnavd's stop, once the terrain thread has ended: the local map under
  // way goes to the trainer if the footprint gave it a positive word.
  bool finish_partial() noexcept;

  const TravLayer& layer() const noexcept { return layer_; }
  // Whether the recorder takes the layer's words (one ground and word per cell).
  bool shares_words() const noexcept { return shared_words_; }
  const OnlineCounters& counters() const noexcept { return counters_; }
  OnlineCounters status() const noexcept { return shared_.read(); }  // any thread

 private:
  void hand_over(bool partial) noexcept;

  TravLayer& layer_;
  TravRecorder* recorder_;
  Mailbox<LocalMapWords>* local_maps_;
  Mailbox<TravModels>* models_in_;
  bool shared_words_ = false;  // the recorder takes the layer's words (same vocabulary)
  OnlineCounters counters_;
  StatusBoard<OnlineCounters> shared_;
};

struct TrainerCounters {
  std::uint64_t trained = 0;        // local maps learnt from
  std::uint64_t without_positive = 0;  // local maps whose footprint gave no word: nothing to learn
  std::uint64_t lost = 0;           // local maps the trainer never saw (it fell a whole local map behind)
  std::uint64_t created = 0;        // terrain models the χ² test opened
  std::uint64_t forced = 0;         // local maps merged into the closest model, none being left to open
  std::uint32_t models = 0;
  std::uint64_t saves = 0;
  std::uint64_t save_failures = 0;
  int save_errno = 0;               // of the last failure (0: none)
};

// The training thread's half.
class TravTrainer {
 public:
  // Starts from `start` (a loaded model, or none) and trains it further; the
  // model file is `path`, kept under `profile`'s name. Allocates here only.
  TravTrainer(const TravModels& start, std::string profile, std::string path, Mailbox<LocalMapWords>& local_maps,
              Mailbox<TravModels>& models_out);

  // Learns from the newest finished local map if one is waiting, hands the
  // models to the layer and saves the file. True when one was learnt from.
  bool poll() noexcept;
  // Saves the file now: 0, or the errno of the failed step.
  int save() noexcept;

  const TravModels& models() const noexcept { return models_; }
  const std::string& path() const noexcept { return file_.path(); }
  const TrainerCounters& counters() const noexcept { return counters_; }
  TrainerCounters status() const noexcept { return shared_.read(); }  // any thread

 private:
  TravModels models_;
  std::string profile_;
  AtomicFile file_;
  std::vector<std::uint8_t> bytes_;  // capacity: the largest file of these models
  Mailbox<LocalMapWords>& local_maps_;
  Mailbox<TravModels>& models_out_;
  std::uint64_t last_sequence_ = 0;
  TrainerCounters counters_;
  StatusBoard<TrainerCounters> shared_;
};

// The thin task around the trainer (trailnavd's `demonstration` task).
class TravTrainingTask final : public Task {
 public:
  explicit TravTrainingTask(TravTrainer& trainer) noexcept : trainer_(trainer) {}
  void run(const TaskTick&) override {
    while (trainer_.poll()) {
    }
  }

 private:
  TravTrainer& trainer_;
};

}  // namespace trailnav::perception::trav
