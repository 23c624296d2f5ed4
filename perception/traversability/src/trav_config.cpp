#include "trailnav/perception/trav_config.hpp"

#include <algorithm>
#include <filesystem>

#include "trailnav/perception/trav_layer.hpp"
#include "trailnav/perception/trav_model_file.hpp"

namespace trailnav::perception::trav {

TraversabilityConfig parse_traversability_config(const ConfigNode& node) {
  TraversabilityConfig c;
  const std::string model = node.string("model");
  const std::filesystem::path p(model);
  c.model = p.is_absolute() || node.file().empty()
                ? model
                : (std::filesystem::path(node.file()).parent_path() / p).lexically_normal().string();
  c.method = node.choice("method", {"pnb", "pos"}, "pnb") == "pos" ? Method::pos : Method::pnb;
  c.features = node.choice("features", {"full", "thesis"}, "full") == "thesis" ? FeatureSet::thesis : FeatureSet::full;
  c.vocabulary.set = c.features;
  c.local_map_distance = node.number("local_map_m", 1.0, 10000.0, c.local_map_distance);
  c.max_range = node.number("max_range_m", 1.0, 300.0, c.max_range);
  if (auto d = node.optional_map("demonstration")) {
    c.demonstration = true;
    c.profile = d->string("profile");
    if (c.profile.empty() || c.profile.size() > kMaxProfileName) d->fail("profile", "1 to 64 characters");
    for (char ch : c.profile) {
      if (ch < 0x21 || ch > 0x7e) d->fail("profile", "printable ASCII without spaces");
    }
    const auto builtin = builtin_footprint(c.profile);
    if (auto f = d->optional_map("footprint")) {
      c.footprint.length = f->number("length_m", 0.05, 50.0);
      c.footprint.width = f->number("width_m", 0.05, 50.0);
      c.footprint.forward = f->number("forward_m", -50.0, 50.0, 0.0);
      f->reject_unknown_keys();
    } else if (builtin) {
      c.footprint = *builtin;
    } else {
      d->fail("footprint", "profile '" + c.profile +
                               "' is not built in (large, small): give its footprint {length_m, width_m, forward_m}");
    }
    c.learner.max_models = static_cast<std::uint32_t>(
        d->integer("max_models", 1, kLayerModels, static_cast<std::int64_t>(c.learner.max_models)));
    c.max_words = static_cast<std::uint32_t>(d->integer("max_words", 1000, 50'000'000, c.max_words));
    d->reject_unknown_keys();
  }
  node.reject_unknown_keys();
  RecorderConfig rc;
  rc.local_map_distance = c.local_map_distance;
  rc.max_range = c.max_range;
  rc.footprint = c.footprint;
  rc.max_words = c.max_words;
  if (c.demonstration) {
    if (const std::string e = check_recorder(rc); !e.empty()) node.fail("demonstration", e);
  }
  return c;
}

StartModels load_start_models(const TraversabilityConfig& c) {
  StartModels out;
  std::error_code ec;
  if (!std::filesystem::exists(c.model, ec)) {
    if (!c.demonstration) {
      out.error = c.model + ": no such file (train one with `trailnav trav-train`, or drive a demonstration: "
                            "traversability.demonstration)";
      return out;
    }
    out.models = std::make_unique<TravModels>(Vocabulary(c.vocabulary), c.learner);
    out.created = true;
    return out;
  }
  LoadedTravModel loaded = load_trav_model(c.model);
  if (!loaded.model) {
    out.error = loaded.error;
    return out;
  }
  const TravModelSet* set = loaded.model->set(c.features);
  if (set == nullptr) {
    out.error = c.model + ": holds no model of the feature set '" + std::string(feature_set_name(c.features)) +
                "' (traversability.features): train one with `trailnav trav-train`";
    return out;
  }
  if (set->models.size() > kLayerModels) {
    out.error = c.model + ": " + std::to_string(set->models.size()) + " terrain models; the layer holds " +
                std::to_string(kLayerModels) + " (train with --max-models " + std::to_string(kLayerModels) + ")";
    return out;
  }
  if (c.demonstration && loaded.model->profile != c.profile) {
    out.error = c.model + ": learnt for the robot profile '" + loaded.model->profile + "', not '" + c.profile +
                "' (demonstration.profile): one robot's traversability is not another's";
    return out;
  }
  LearnerConfig learner = set->learner;
  if (c.demonstration) learner.max_models = std::min(learner.max_models, kLayerModels);
  out.models = std::make_unique<TravModels>(Vocabulary(set->vocabulary), learner);
  out.models->set_models(set->models);
  out.other_sets = loaded.model->sets.size() - 1;
  return out;
}

}  // namespace trailnav::perception::trav
