#include "place_eval.hpp"

#include "number_rows.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>

#include "trailnav/drivers/camera/image_file.hpp"
#include "trailnav/perception/place/online.hpp"
#include "trailnav/perception/place/similarity.hpp"

namespace trailnav::eval {

namespace place = perception::place;
namespace camera = drivers::camera;

namespace {

constexpr int kDefaultTolerance = 5;  // the thesis' "fewer than six frames"

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

struct Sequence {
  std::vector<camera::GreyImage> images;
  std::string error;
};

Sequence read_sequence(const std::string& dir, int subsample, int max_images, const std::string& stage,
                       const PlaceEvalOptions& o) {
  Sequence out;
  camera::ImageList list = camera::list_images(dir);
  if (!list.error.empty()) {
    out.error = list.error;
    return out;
  }
  std::vector<std::string> paths;
  for (std::size_t i = 0; i < list.paths.size(); i += static_cast<std::size_t>(subsample)) paths.push_back(list.paths[i]);
  if (max_images > 0 && paths.size() > static_cast<std::size_t>(max_images)) paths.resize(static_cast<std::size_t>(max_images));
  for (std::size_t i = 0; i < paths.size(); ++i) {
    camera::ImageRead r = camera::read_grey_image(paths[i]);
    if (!r.ok()) {
      out.error = r.error;
      return out;
    }
    if (!out.images.empty() &&
        (r.image.width != out.images.front().width || r.image.height != out.images.front().height)) {
      out.error = paths[i] + ": " + std::to_string(r.image.width) + " x " + std::to_string(r.image.height) +
                  " pixels where the sequence's first image has " + std::to_string(out.images.front().width) + " x " +
                  std::to_string(out.images.front().height) + ": a sequence's images must share one size";
      return out;
    }
    out.images.push_back(std::move(r.image));
    if (o.progress && (i % 64 == 0 || i + 1 == paths.size()))
      o.progress(stage, static_cast<double>(i + 1) / static_cast<double>(paths.size()));
  }
  return out;
}

// Ground truth in the query directory's and the database directory's own
// indices (0-based, after subsampling): reference and tolerance per query.
bool read_truth(const PlaceEvalOptions& o, std::size_t queries, std::size_t database, std::vector<int>& reference,
                std::vector<int>& tolerance, std::string& error) {
  reference.assign(queries, -1);
  tolerance.assign(queries, o.tolerance >= 0 ? o.tolerance : kDefaultTolerance);
  if (o.ground_truth == "same-index") {
    for (std::size_t i = 0; i < queries; ++i) reference[i] = i < database ? static_cast<int>(i) : -1;
    return true;
  }
  error = read_number_rows(
      o.ground_truth, 2, 3, "`query,reference[,tolerance]` (1-based indices)", [&](int, std::span<const double> f) {
        const double q = f[0], r = f[1], t = f.size() > 2 ? f[2] : -1.0;
        if (q < 1 || r < 1 || t < -1 || q != std::floor(q) || r != std::floor(r) || t != std::floor(t))
          return std::string("indices are whole and 1-based, the tolerance whole and not negative");
        if (q > static_cast<double>(queries)) return std::string();  // beyond the queries read (--max-images)
        const auto qi = static_cast<std::size_t>(q - 1);
        reference[qi] = r <= static_cast<double>(database) ? static_cast<int>(r - 1) : -1;
        if (o.tolerance < 0 && t >= 0) tolerance[qi] = static_cast<int>(t);
        return std::string();
      });
  return error.empty();
}

// Matches from the case's database positions to the directory's indices.
void to_directory(std::vector<place::Match>& matches, const std::vector<int>& kept) {
  for (place::Match& m : matches) m.database = kept[static_cast<std::size_t>(m.database)];
}

// Peaks in the case's database positions (the sequence filter's column gap
// counts positions of the database as it is), scored in the directory's.
place::PrCurve sequence_curve(const std::vector<place::Match>& peaks, const place::SequenceConfig& config,
                              const place::GroundTruth& truth, const std::vector<int>& positions,
                              std::vector<place::Match>& best_matches) {
  std::vector<float> scores;
  scores.reserve(peaks.size());
  for (const place::Match& m : peaks) scores.push_back(m.score);
  std::sort(scores.begin(), scores.end(), std::greater<>());
  // Thresholds at geometrically spaced ranks of the peaks' scores.
  std::vector<float> thresholds;
  for (double rank = 1.0; rank < static_cast<double>(scores.size()); rank *= 1.08) {
    const float t = scores[static_cast<std::size_t>(rank)];
    if (thresholds.empty() || t < thresholds.back()) thresholds.push_back(t);
  }
  if (!scores.empty() && (thresholds.empty() || scores.back() < thresholds.back())) thresholds.push_back(scores.back());
  std::vector<place::PrPoint> points;
  std::vector<place::Match> above;
  double best_f1 = -1.0;
  for (float t : thresholds) {
    above.clear();
    for (const place::Match& m : peaks)
      if (m.score >= t) above.push_back(m);
    std::vector<place::Match> kept = place::sequence_filter(above, config);
    to_directory(kept, positions);
    const place::PrPoint p = place::score(kept, truth, t);
    if (p.matches > 0 && p.f1 > best_f1) {
      best_f1 = p.f1;
      best_matches = kept;
    }
    points.push_back(p);
  }
  return place::curve_of(std::move(points));
}

std::vector<place::Match> best_of_sweep(const std::vector<place::Match>& matches, double threshold) {
  std::vector<place::Match> out;
  for (const place::Match& m : matches)
    if (static_cast<double>(m.score) >= threshold) out.push_back(m);
  return out;
}

}  // namespace

bool scattered_case(const std::string& name, int images, ScatteredCase& out) {
  out = {};
  int which = 0;
  if (name == "scattered-1") which = 1;
  if (name == "scattered-2") which = 2;
  if (name == "scattered-3") which = 3;
  if (which == 0 || images < 200) return false;
  std::mt19937 rng(static_cast<std::uint32_t>(4100 + which));
  // Chunks of 20-150 images cover the sequence; the database loses a
  // stretch of an eighth of it (queries there have no place).
  std::vector<std::pair<int, int>> chunks;
  for (int at = 0; at < images;) {
    const int len = std::min(images - at, std::uniform_int_distribution<int>(20, 150)(rng));
    chunks.emplace_back(at, at + len);
    at += len;
  }
  const int gap = images / 8;
  out.database_gap_begin = std::uniform_int_distribution<int>(images / 4, images - images / 4 - gap)(rng);
  out.database_gap_end = out.database_gap_begin + gap;
  // Shuffled; case 1 revisits a fifth of the chunks, case 2 a third, case 3
  // keeps long runs in order between jumps (the chunks in order in blocks of
  // three, the blocks shuffled) and revisits a tenth.
  std::vector<std::pair<int, int>> order = chunks;
  if (which == 3) {
    std::vector<std::vector<std::pair<int, int>>> blocks;
    for (std::size_t i = 0; i < chunks.size(); i += 3)
      blocks.emplace_back(chunks.begin() + static_cast<long>(i), chunks.begin() + static_cast<long>(std::min(chunks.size(), i + 3)));
    std::shuffle(blocks.begin(), blocks.end(), rng);
    order.clear();
    for (const auto& b : blocks) order.insert(order.end(), b.begin(), b.end());
  } else {
    std::shuffle(order.begin(), order.end(), rng);
  }
  const double revisit = which == 1 ? 0.2 : which == 2 ? 1.0 / 3.0 : 0.1;
  const std::size_t extra = static_cast<std::size_t>(std::lround(revisit * static_cast<double>(chunks.size())));
  for (std::size_t k = 0; k < extra; ++k) {
    const auto& c = chunks[std::uniform_int_distribution<std::size_t>(0, chunks.size() - 1)(rng)];
    const std::size_t at = std::uniform_int_distribution<std::size_t>(0, order.size())(rng);
    order.insert(order.begin() + static_cast<long>(at), c);
  }
  for (const auto& [b, e] : order)
    for (int i = b; i < e; ++i) out.query_order.push_back(i);
  return true;
}

PlaceEvalReport run_place_eval(const PlaceEvalOptions& o) {
  PlaceEvalReport r;
  if (o.subsample < 1) {
    r.error = "--subsample must be at least 1";
    return r;
  }
  Sequence db = read_sequence(o.database, o.subsample, o.max_images, "reading the database", o);
  if (!db.error.empty()) {
    r.error = db.error;
    return r;
  }
  Sequence qs = read_sequence(o.query, o.subsample, o.max_images, "reading the queries", o);
  if (!qs.error.empty()) {
    r.error = qs.error;
    return r;
  }
  const camera::GreyImage& first = db.images.front();
  if (qs.images.front().width != first.width || qs.images.front().height != first.height) {
    r.error = "the database's images are " + std::to_string(first.width) + " x " + std::to_string(first.height) +
              " pixels and the queries' " + std::to_string(qs.images.front().width) + " x " +
              std::to_string(qs.images.front().height) + ": both must have one size";
    return r;
  }
  // The case: which database images stay, and the queries' order.
  std::vector<int> kept;  // case database position -> directory index
  ScatteredCase sc;
  if (o.case_name == "connected") {
    for (std::size_t i = 0; i < qs.images.size(); ++i) r.query_order.push_back(static_cast<int>(i));
    for (std::size_t j = 0; j < db.images.size(); ++j) kept.push_back(static_cast<int>(j));
  } else if (scattered_case(o.case_name, static_cast<int>(std::min(qs.images.size(), db.images.size())), sc)) {
    r.query_order = sc.query_order;
    for (int j = 0; j < static_cast<int>(db.images.size()); ++j)
      if (j < sc.database_gap_begin || j >= sc.database_gap_end) kept.push_back(j);
  } else {
    r.error = "--case takes connected, scattered-1, scattered-2 or scattered-3 (a scattered case needs 200 images), not '" +
              o.case_name + "'";
    return r;
  }
  r.database_images = kept.size();
  r.query_images = r.query_order.size();
  r.width = first.width;
  r.height = first.height;
  const bool have_truth = !o.ground_truth.empty();
  if (have_truth) {
    std::vector<int> reference, tolerance;
    if (!read_truth(o, qs.images.size(), db.images.size(), reference, tolerance, r.error)) return r;
    // Per query of the case; a query has a place when a kept database image
    // lies within its tolerance of the reference.
    for (int q : r.query_order) {
      int ref = reference[static_cast<std::size_t>(q)];
      const int tol = tolerance[static_cast<std::size_t>(q)];
      if (ref >= 0) {
        const auto lo = std::lower_bound(kept.begin(), kept.end(), ref - tol);
        if (lo == kept.end() || *lo > ref + tol) ref = -1;
      }
      r.truth.reference.push_back(ref);
      r.truth.tolerance.push_back(tol);
    }
    r.positives = r.truth.positives();
  }

  // Descriptors.
  auto t0 = std::chrono::steady_clock::now();
  place::Hog hog(o.hog, first.width, first.height);
  r.descriptor_length = hog.length();
  r.patch = hog.config().patch;
  std::vector<float> f(static_cast<std::size_t>(hog.length()));
  const auto len = static_cast<Eigen::Index>(hog.length());
  place::Matrix s;
  place::Matrix dd_keep;
  place::CompactDescriptors cd_keep;
  {
    place::Matrix dq(static_cast<Eigen::Index>(r.query_images), len), dd(static_cast<Eigen::Index>(kept.size()), len);
    place::CompactDescriptors cq, cd;
    const std::size_t total = kept.size() + r.query_images;
    std::size_t done = 0;
    const auto describe = [&](const camera::GreyImage& im, place::Matrix& m, Eigen::Index row, place::CompactDescriptors& c) {
      hog.compute(im.pixels, im.width, f);
      if (o.compact) {
        c.add(f);
      } else {
        for (Eigen::Index k = 0; k < len; ++k) m(row, k) = f[static_cast<std::size_t>(k)];
      }
      ++done;
      if (o.progress && (done % 64 == 0 || done == total)) o.progress("HOG descriptors", static_cast<double>(done) / static_cast<double>(total));
    };
    for (std::size_t j = 0; j < kept.size(); ++j)
      describe(db.images[static_cast<std::size_t>(kept[j])], dd, static_cast<Eigen::Index>(j), cd);
    for (std::size_t i = 0; i < r.query_images; ++i)
      describe(qs.images[static_cast<std::size_t>(r.query_order[i])], dq, static_cast<Eigen::Index>(i), cq);
    r.descriptor_bytes = o.compact ? static_cast<std::size_t>(hog.length()) + sizeof(float)
                                   : static_cast<std::size_t>(hog.length()) * sizeof(float);
    r.seconds_descriptors = seconds_since(t0);
    t0 = std::chrono::steady_clock::now();
    s = o.compact ? place::cosine_similarities(cq, cd) : place::cosine_similarities(dq, dd);
    r.seconds_similarity = seconds_since(t0);
    if (o.zca_from_database || o.online) {
      dd_keep = std::move(dd);
      cd_keep = std::move(cd);
    }
  }
  // A method whose matches are thresholded on their own scores (raw,
  // filter, SeqSLAM): swept here; the sequence filter's curve is made per
  // threshold (sequence_curve) and handed over whole.
  const auto add_method = [&](const std::string& name, place::PrCurve curve, std::vector<place::Match> matches) {
    r.methods.push_back({name, std::move(curve), std::move(matches)});
  };
  const auto add_swept = [&](const std::string& name, std::vector<place::Match> scored) {
    to_directory(scored, kept);
    if (!have_truth) return add_method(name, {}, std::move(scored));
    place::PrCurve c = place::sweep(scored, r.truth);
    std::vector<place::Match> best = best_of_sweep(scored, c.best.threshold);
    add_method(name, std::move(c), std::move(best));
  };

  // Raw best match.
  {
    std::vector<place::Match> raw;
    for (Eigen::Index i = 0; i < s.rows(); ++i) {
      Eigen::Index j = 0;
      const float v = s.row(i).maxCoeff(&j);
      raw.push_back({static_cast<int>(i), static_cast<int>(j), v});
    }
    add_swept("raw", std::move(raw));
  }
  const float uniform = 1.0f / static_cast<float>(kept.size());
  const auto filtered = [&](const place::Matrix& likelihood, const std::string& name) {
    const auto t1 = std::chrono::steady_clock::now();
    const place::Matrix b = place::forward_backward(likelihood, o.transition);
    // Without the sequence filter: each query's most likely place (the
    // filter's answer, as raw's is the best similarity), thresholded on its
    // belief.
    std::vector<place::Match> most_likely;
    for (Eigen::Index i = 0; i < b.rows(); ++i) {
      Eigen::Index j = 0;
      const float v = b.row(i).maxCoeff(&j);
      most_likely.push_back({static_cast<int>(i), static_cast<int>(j), v});
    }
    add_swept(name, std::move(most_likely));
    // With it: every local peak (a database revisited holds several), kept
    // in sequences.
    std::vector<place::Match> peaks = place::row_peaks(b, uniform, o.peak_radius);
    if (have_truth) {
      std::vector<place::Match> best;
      place::PrCurve c = sequence_curve(peaks, o.sequence, r.truth, kept, best);
      add_method(name + "+seq", std::move(c), std::move(best));
    } else {
      std::vector<place::Match> in_sequences = place::sequence_filter(peaks, o.sequence);
      to_directory(in_sequences, kept);
      add_method(name + "+seq", {}, std::move(in_sequences));
    }
    r.seconds_filters += seconds_since(t1);
  };
  if (o.progress) o.progress("filters", 0.0);
  {
    place::Matrix l = s;
    place::normalise_columns(l);  // Eq. 5.3
    place::stretch_rows(l);       // Eq. 5.4
    filtered(l, "filter");
  }
  if (o.progress) o.progress("ZCA whitening", 0.0);
  {
    t0 = std::chrono::steady_clock::now();
    place::Matrix l;
    if (o.zca_from_database) {
      const place::Matrix dd = o.compact ? place::cosine_similarities(cd_keep, cd_keep) : place::cosine_similarities(dd_keep, dd_keep);
      l = place::zca_whiten_with(dd, s, o.zca_epsilon);
    } else if (o.zca_after_columns) {
      place::Matrix c = s;
      place::normalise_columns(c);
      l = place::zca_whiten(c, o.zca_epsilon);
    } else {
      l = place::zca_whiten(s, o.zca_epsilon);
    }
    place::stretch_rows(l);
    r.seconds_zca = seconds_since(t0);
    if (o.progress) o.progress("ZCA whitening", 1.0);
    filtered(l, "zca+filter");
  }
  if (o.progress) o.progress("filters", 1.0);
  if (o.online) {
    t0 = std::chrono::steady_clock::now();
    if (o.progress) o.progress("online filter", 0.0);
    place::OnlineConfig oc;
    oc.hog = hog.config();
    oc.transition = o.transition;
    oc.width = first.width;
    oc.height = first.height;
    oc.capacity = kept.size();
    oc.lag = o.online_lag;
    oc.sequence = o.online_sequence;
    oc.peak_radius = o.peak_radius;
    place::OnlinePlace online(oc);
    place::CompactDescriptors codes;
    if (o.compact) {
      codes = std::move(cd_keep);
    } else {
      std::vector<float> row(static_cast<std::size_t>(len));
      for (Eigen::Index j = 0; j < dd_keep.rows(); ++j) {
        for (Eigen::Index k = 0; k < len; ++k) row[static_cast<std::size_t>(k)] = dd_keep(j, k);
        codes.add(row);
      }
    }
    for (std::size_t j = 0; j < kept.size(); ++j) online.add_database_code(codes.code(j), codes.norms[j]);
    online.finish_database();
    if (o.online_zca_rank > 0)
      online.set_whitening(place::learn_whitening(codes.codes, codes.norms, hog.length(), o.online_zca_rank, o.online_zca_epsilon));
    std::vector<place::Match> causal, lagged, in_sequence;
    std::vector<float> row(kept.size());
    for (Eigen::Index i = 0; i < s.rows(); ++i) {
      for (std::size_t j = 0; j < kept.size(); ++j) row[j] = s(i, static_cast<Eigen::Index>(j));
      const place::PlaceEstimate e = online.step_similarities(row);
      causal.push_back({static_cast<int>(i), e.index, static_cast<float>(e.probability)});
      const place::LaggedEstimate& l = online.lagged();
      if (l.valid && l.index >= 0) {
        const place::Match m{static_cast<int>(l.step), l.index, static_cast<float>(l.probability)};
        lagged.push_back(m);
        if (l.in_sequence) in_sequence.push_back(m);
      }
      if (o.progress && (i % 64 == 0 || i + 1 == s.rows()))
        o.progress("online filter", static_cast<double>(i + 1) / static_cast<double>(s.rows()));
    }
    add_swept("online", std::move(causal));
    add_swept("online+lag", std::move(lagged));
    add_swept("online+lag+seq", std::move(in_sequence));
    r.seconds_online = seconds_since(t0);
  }
  if (o.seqslam) {
    t0 = std::chrono::steady_clock::now();
    std::vector<std::vector<float>> pd, pq;
    for (int j : kept) {
      const camera::GreyImage& im = db.images[static_cast<std::size_t>(j)];
      pd.push_back(seqslam_prepare(im.pixels, im.width, im.height, o.seqslam_config));
    }
    for (int q : r.query_order) {
      const camera::GreyImage& im = qs.images[static_cast<std::size_t>(q)];
      pq.push_back(seqslam_prepare(im.pixels, im.width, im.height, o.seqslam_config));
    }
    if (o.progress) o.progress("SeqSLAM", 0.0);
    add_swept("seqslam", seqslam_matches(pd, pq, o.seqslam_config));
    if (o.progress) o.progress("SeqSLAM", 1.0);
    r.seconds_seqslam = seconds_since(t0);
  }
  return r;
}

}  // namespace trailnav::eval
