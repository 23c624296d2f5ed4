#include "trailnav/perception/trav_online.hpp"

#include <algorithm>
#include <cerrno>

#include "trailnav/perception/trav_model_file.hpp"

namespace trailnav::perception::trav {

TravOnline::TravOnline(TravLayer& layer, TravRecorder* recorder, Mailbox<LocalMapWords>* local_maps,
                       Mailbox<TravModels>* models_in) noexcept
    : layer_(layer), recorder_(recorder), local_maps_(local_maps), models_in_(models_in) {
  if (recorder_ == nullptr || local_maps_ == nullptr) {
    recorder_ = nullptr;
    local_maps_ = nullptr;
  }
  // The layer works out each cell's ground and word once for both halves
  // when the recorder's vocabulary is its models' (trailnavd's is: the
  // demonstration trains the model the layer classifies with).
  shared_words_ = recorder_ != nullptr && recorder_->vocabulary().config() == layer_.models().vocabulary().config();
  counters_.models = layer_.models().models();
  shared_.post(counters_);
}

void TravOnline::cell_sums(CellIndex cell, const CellStats& sums, const FeatureVector* feature, double x,
                           double y) noexcept {
  if (shared_words_) {
    const bool within = !recorder_->too_far(x, y);  // the recorder's own range, counted by it
    std::uint32_t word = 0;
    if (layer_.classify(cell, sums, feature, x, y, word) && within) recorder_->record(cell, word);
    return;
  }
  layer_.cell_sums(cell, sums, feature, x, y);
  if (recorder_ != nullptr) recorder_->cell_sums(cell, sums, feature, x, y);
}

void TravOnline::robot_pose(double x, double y, double yaw, std::int64_t) noexcept {
  if (recorder_ == nullptr) return;
  recorder_->drive(x, y, yaw);
  if (recorder_->local_map_complete()) hand_over(false);
}

void TravOnline::hand_over(bool partial) noexcept {
  LocalMapWords& slot = local_maps_->write_slot();
  recorder_->finish_local_map(slot.counts);
  if (partial && slot.counts.total_positive() == 0) return;
  local_maps_->publish();
  ++counters_.handed;
}

void TravOnline::step_begins(double robot_x, double robot_y, std::int64_t now_ns, TerrainClassMap& map) noexcept {
  if (models_in_ != nullptr) {
    if (const TravModels* m = models_in_->try_read()) {
      layer_.set_models(*m);
      ++counters_.model_updates;
    }
  }
  layer_.step_begins(robot_x, robot_y, now_ns, map);
  // The counters of the step before (this one's cells follow): posted once a step.
  counters_.layer = layer_.counters();
  if (recorder_ != nullptr) counters_.recorder = recorder_->counters();
  counters_.models = std::min(layer_.models().models(), kLayerModels);
  shared_.post(counters_);
}

bool TravOnline::finish_partial() noexcept {
  if (recorder_ == nullptr) return false;
  const std::uint64_t before = counters_.handed;
  hand_over(true);
  counters_.recorder = recorder_->counters();
  shared_.post(counters_);
  return counters_.handed > before;
}

TravTrainer::TravTrainer(const TravModels& start, std::string profile, std::string path,
                         Mailbox<LocalMapWords>& local_maps, Mailbox<TravModels>& models_out)
    : models_(start),
      profile_(std::move(profile)),
      file_(std::move(path)),
      local_maps_(local_maps),
      models_out_(models_out) {
  bytes_.reserve(trav_model_bound(profile_.size(), models_.vocabulary().size(), models_.config().max_models));
  counters_.models = models_.models();
  shared_.post(counters_);
}

bool TravTrainer::poll() noexcept {
  const LocalMapWords* in = local_maps_.try_read();
  if (in == nullptr) return false;
  const std::uint64_t sequence = local_maps_.last_read_sequence();
  if (sequence > last_sequence_ + 1) counters_.lost += sequence - last_sequence_ - 1;
  last_sequence_ = sequence;
  const TravModels::Assignment a = models_.train(in->counts);
  if (a.model < 0) {
    ++counters_.without_positive;
    shared_.post(counters_);
    return true;
  }
  ++counters_.trained;
  if (a.created) ++counters_.created;
  if (a.forced) ++counters_.forced;
  counters_.models = models_.models();
  // The layer's copy: same tables, so the assignment copies in place.
  models_out_.write_slot() = models_;
  models_out_.publish();
  save();
  return true;
}

int TravTrainer::save() noexcept {
  serialize_trav_models(profile_, models_, bytes_);
  const int e = file_.write(bytes_);
  if (e == 0) {
    ++counters_.saves;
  } else {
    ++counters_.save_failures;
    counters_.save_errno = e;
  }
  shared_.post(counters_);
  return e;
}

}  // namespace trailnav::perception::trav
