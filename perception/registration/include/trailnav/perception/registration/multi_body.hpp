// Generalized ICP for several rigid bodies at once (thesis §4.1.1,
// Eq. 4.1–4.4): a reference made of objects j = 1..n (a station's table,
// shelf, box, and the static surroundings), each with its own transform
// T_j that maps the local point set Q into the object's reference frame.
// Each query point q_i is associated with the nearest reference point over
// all objects, each under its own current transform (Eq. 4.2: the Dirac
// weight ω_ij = 1 for that object, 0 for the others), and all transforms are
// solved for jointly (Eq. 4.1 / 4.4). With Dirac weights the objective is a
// sum over objects of single-body GICP terms, so given the associations the
// joint Gauss–Newton system is block diagonal: each object's 6 × 6 block is
// solved on its own, the association couples them. The metric is a choice of
// covariances as in gicp.hpp (the thesis used point-to-plane).
//
// Iterated until every object's update is below the convergence thresholds
// or `max_iterations`. An object with fewer than 6 associations in an
// iteration keeps its transform (it is out of view) and is reported so; when
// no object has them, the iterations stop. Gicp (gicp.hpp) is this solver
// with one body.
// Preallocated for `capacity` query points and `max_bodies` objects.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "trailnav/perception/registration/gicp.hpp"

namespace trailnav::perception::registration {

struct BodyResult {
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();  // query -> object's reference frame
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();
  // The final normal matrix H = Σ Jᵀ M J itself ((ω, v) order): a planar
  // problem's is singular out of the plane, and its (ω_z, v_x, v_y) block
  // inverted is the in-plane covariance (station_task.cpp).
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
  std::size_t correspondences = 0;  // query points associated with it in the last iteration
  bool converged = false;           // its last update below the thresholds
  bool observed = false;            // at least 6 associations in the last iteration
  double fitness = 0.0;             // mean squared Euclidean distance of its last associations, m²
  double error = 0.0;               // its share of the objective (Eq. 4.1) at the last associations
};

class MultiBodyGicp {
 public:
  MultiBodyGicp(const GicpConfig& config, std::size_t capacity, std::size_t max_bodies);

  // Aligns `query` to every body at once from `initial` (one transform per
  // body); writes one result per body into `out` (its size: the bodies').
  // Returns the iterations run. At most max_bodies bodies and `capacity`
  // query points are used.
  int align(const Cloud& query, std::span<const Target* const> bodies, std::span<const Eigen::Isometry3d> initial,
            std::span<BodyResult> out) noexcept;

 private:
  struct Pair {
    std::uint32_t query;
    std::uint32_t target;
    std::uint32_t body;
    float squared;  // the association's squared distance
  };
  GicpConfig config_;
  std::size_t max_bodies_;
  std::vector<Pair> pairs_;
  std::vector<Eigen::Matrix<double, 6, 6>> h_;
  std::vector<Eigen::Matrix<double, 6, 1>> b_;
  // Each query point's partner in the last iteration (body, target point;
  // kNone: none): its distance under the new transforms bounds the next
  // search, so the k-d tree visits only what may lie closer.
  static constexpr std::uint32_t kNone = 0xffffffffu;
  std::vector<std::uint32_t> previous_body_, previous_target_;
  // One body: where each query point's last search took place (in the
  // target frame), the distance to the nearest point found there and a
  // lower bound of the distance to every other point (the second nearest,
  // or the gate). A point that has since moved by δ with
  // nearest + 2δ < second still has that nearest point: no search.
  void associate_everywhere(const Cloud& query, std::span<const Target* const> bodies, std::span<BodyResult> out,
                            std::size_t nb, std::size_t n, bool to_plane, float gate2) noexcept;
  void associate_one(const Cloud& query, const Target& body, const Eigen::Isometry3d& transform, std::size_t n,
                     bool to_plane, float gate2, float gate_bound) noexcept;
  struct Searched {
    Eigen::Vector3f at;
    float nearest;  // m
    float second;   // m
  };
  std::vector<Searched> searched_;
  std::uint64_t searches_ = 0, kept_ = 0;
  bool search_every_point_ = false;

 public:
  // For tests and measurements: search the whole tree for every query point
  // in every iteration, unbounded, as before the shortcuts above. The
  // partners, and so the answers, are the same bit for bit.
  void search_every_point(bool on) noexcept { search_every_point_ = on; }
  // Association counters since construction: k-d tree searches, and
  // associations kept without one (single body).
  std::uint64_t searches() const noexcept { return searches_; }
  std::uint64_t kept() const noexcept { return kept_; }
};

}  // namespace trailnav::perception::registration
