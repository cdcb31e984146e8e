// Physics-based registration of the liver model to intra-operative point clouds, ROS-free.
//
// Each frame: the cloud (model frame, m) is cropped to the model's neighbourhood, downsampled on
// a voxel grid, optionally moved by a rigid alignment found once with PCL's ICP; then, a few
// times, every point finds its closest point on the boundary triangles (SurfaceLocator, exact),
// far points are rejected (distance
// gate, then trimming), the rest are weighted (Huber), and they pull the surface through
// springs (LiverModel::set_surface_targets) while the model solves its equilibrium, starting
// from the last frame's state. The springs stay until the next cloud, so the model keeps the
// registered shape; the elasticity carries the visible surface's motion to the hidden tumour
// and vessels.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <chrono>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/geometry/closest_points.h"
#include "liver_sim/registration/cloud_filter.h"
#include "liver_sim/registration/one_shot.h"
#include "liver_sim/registration/tracked_targets.h"
#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/registration/state_compliance.h"
#include "liver_sim/geometry/surface_locator.h"
#include "liver_sim/registration/surface_patches.h"

namespace liver_sim {

struct RegistrationFrame {
  int input_points = 0;      // finite points received
  int used_points = 0;       // after cropping, voxel grid and stride
  int correspondences = 0;   // accepted (not gated, not trimmed) at the last update
  double inlier_fraction = 0;  // correspondences / used_points
  double coverage = 0;       // share of the boundary area on triangles that hold an accepted point
  double stiffness_scale = 0;  // the springs' total over options.stiffness: min(1, coverage / full_coverage)
  double rms = 0;            // m: the accepted points' spring lengths after the solve (along the
                             // normal for point-to-plane): their distance to the surface
  double rms_all = 0;        // m: every used point's distance after the solve to the triangle
                             // its last correspondence update found, those beyond max_distance
                             // counted at max_distance (outliers and trimmed points included: it
                             // cannot look better than the cloud fits the surface; it exceeds
                             // that by at most twice the surface's motion since the update)
  StepResult step;           // the last solve (its status: converged, capped or rolled back)
  int updates = 0;           // correspondence updates solved in this frame
  int newton_iterations = 0; // over all updates of this frame
  int factorizations = 0;    // CHOLMOD factorisations, over all updates
  bool hidden_loads_reverted = false;  // a step diverged while new hidden loads acted: the ones before them act again
  double filter_ms = 0, correspondence_ms = 0, solve_ms = 0, total_ms = 0;
};

class SurfaceRegistration {
 public:
  // Throws std::invalid_argument for invalid options (validate(RegistrationOptions)) and for a
  // candidate support that selects no free surface node of the rest shape.
  SurfaceRegistration(LiverModel& model, const RegistrationOptions& options);

  // Registers the model to a cloud in the model frame (m), seen from `viewpoint` (the sensor's
  // origin in the model frame) when known: then only triangles facing it correspond. Non-finite
  // points are dropped. Throws std::invalid_argument, with nothing changed, when no finite point
  // remains, none lies within max_distance of the model's bounding box or of its surface, no
  // triangle faces the viewpoint, fewer than min_points are accepted, or they cover less than
  // min_coverage of the surface. The springs share stiffness x min(1, coverage / full_coverage):
  // a small patch pulls no harder per area than a full view. A model step that throws (rolled
  // back) takes its update's springs with it and the exception goes on: thrown by the cloud's
  // first solve, nothing changed, as for a refusal; by a later one, the cloud stands with the
  // springs of its last update that stepped, as does refine()'s.
  RegistrationFrame register_cloud(const pcl::PointCloud<pcl::PointXYZ>& cloud,
                                   const std::optional<Eigen::Vector3d>& viewpoint = std::nullopt);

  // One-shot registration (one_shot.h) of an organ deformed beyond what the frame-to-frame
  // tracking reaches (the first cloud, or on request), its attachments unknown: `one_shot`
  // (built from the same mesh and scene as the model) finds the rigid motion and the surface
  // loads from the rest shape, starting from the current alignment. The registration then
  // starts again from there (clear(), then): the model takes the registered shape, held there by
  // the loads that hold it (its internal forces less the scene's loads at that shape and less
  // the instruments' forces at the model's state, the one-shot's reference; its supports stay
  // where the shape put them), the rigid motion becomes the alignment applied to
  // every cloud, and the cloud is registered as by register_cloud, so that tracking goes on.
  // Throws std::invalid_argument, with nothing changed, for a cloud the one-shot registration
  // refuses (one_shot.h) or a one-shot registration of another mesh; a refusal of the cloud by
  // register_cloud comes after the hand-over.
  struct OneShotReport {
    OneShotResult one_shot;
    RegistrationFrame frame;
  };
  OneShotReport register_one_shot(OneShotRegistration& one_shot, const pcl::PointCloud<pcl::PointXYZ>& cloud,
                                  const std::optional<Eigen::Vector3d>& viewpoint = std::nullopt);
  // The hand-over alone, of a one-shot result found elsewhere (another thread, from the
  // alignment in force when it started) for `cloud`: what register_one_shot does after the
  // solve. Throws std::invalid_argument, with nothing changed, for a result of another mesh.
  // `instrument_forces`: the instruments' contact forces on the tissue (per DOF, N; zeros when
  // none touched it) at the shape the solve started from (OneShotRegistration::set_reference), which that shape
  // and so the result carry: the loads holding the shape leave them out, since the instruments
  // in the model press by themselves (where they are now, not where they were).
  RegistrationFrame adopt_one_shot(const OneShotResult& result, const pcl::PointCloud<pcl::PointXYZ>& cloud,
                                   const std::optional<Eigen::Vector3d>& viewpoint,
                                   const Eigen::VectorXd& instrument_forces);

  // The last cloud's next correspondence updates (up to options.frame_updates of those its
  // register_cloud left, fewer once the scene's solver.time_budget is spent: the first always
  // runs), or, once all are done, one more solve with its springs; with the
  // registration's solver settings. The node converges the model on the last cloud between
  // clouds, in steps short enough that the next cloud waits for one iteration. (After the
  // updates the springs stay put: correspondences that switch triangles would keep the residual
  // from reaching the tolerance.)
  RegistrationFrame refine();
  // The last cloud has correspondence updates left for refine().
  bool updates_pending() const { return updates_left_ > 0; }

  // The next cloud is rigidly aligned first (ICP from the current alignment), whatever
  // options.rigid_alignment says: a camera moved or was recalibrated.
  void request_rigid_alignment() { align_requested_ = true; }

  // Attachments the segmentation did not show. A candidate support (options.candidate_supports)
  // is held, from the model's next step, when holding it would take at least
  // options.support_gain of the springs' systematic pull away: the surface the camera sees is
  // free of forces in surgery (but for the instruments), so a net pull of the springs on a
  // patch of it (a few cm, where the sensor's noise cancels) measures what the model gets wrong. `springs` are the cloud's
  // springs `compliance` was factorised with (cloud_springs() then). Each candidate not held is
  // tried linearised at x, the equilibrium the state `compliance` was factorised at is on its
  // way to (StateCompliance::equilibrium): a reaction spread over its nodes holding their mean
  // at rest, R = (Phi^T A^-1 Phi)^-1 Phi^T (X - x), moves the state by A^-1 Phi R, and the pull
  // is evaluated there. The best one is held (at most one per call: the next call sees its
  // effect); held candidates stay held until clear(). Returns the candidate newly held, or
  // -1. Costs one solve with three columns per candidate.
  int estimate_supports(StateCompliance& compliance, const std::vector<SurfaceTarget>& springs);
  // The tissue's stiffness factor (LiverModel::set_stiffness_scale) the clouds call for: the
  // surface the camera sees is free of forces (but for the instruments), so the springs' net
  // pull on the patches they touch, r_p, measures what the model gets wrong; a model too soft
  // sags where the cloud does not, a model too stiff resists the cloud's deformation. One
  // Gauss-Newton step on ln s minimising sum_p |r_p|^2, linearised at the equilibrium of the
  // state `compliance` was factorised at with its springs (as estimate_supports): a factor e^t
  // moves that equilibrium by -t A^-1 f_int (f_int there: the forces applied there, balanced),
  // which changes r_p by t J_p, so t = -sum r_p.J_p / sum |J_p|^2 (at most a factor 2 per
  // call, the factor within [options.min_tissue_stiffness_factor,
  // options.max_tissue_stiffness_factor]). Applied to the model from its next step; successive
  // calls (one per analysis) converge it. Returns the factor (unchanged when both bounds are 1).
  // Costs one solve with one column.
  double estimate_tissue_stiffness(StateCompliance& compliance, const std::vector<SurfaceTarget>& springs);

  // Loads on the surface the camera does not see (options.estimate_hidden_loads): the surface it
  // sees is free of forces (but for the instruments), so the springs' net pull r_p on the
  // patches they touch is what the model lacks, and in surgery the forces that deform the liver
  // act where the camera does not look (the diaphragm, a retractor, a ligament). One damped
  // Gauss-Newton step on a force per untouched patch (its unit force spread as in
  // SurfacePatches), g, linearised at the equilibrium of the state `compliance` was factorised
  // at with its springs (as estimate_supports): g moves the state by A^-1 Phi g, which changes
  // r_p by J_p g; minimises sum_p w_p |r_p + J_p dg|^2 + lambda |g + dg|^2, w_p Huber weights
  // of width twice the median |r_p| (as the stiffness estimate), lambda =
  // options.hidden_load_damping times the mean diagonal of J^T W J (the loads stay the smallest
  // that explain the pull). A patch
  // the springs touch carries no load: one that had a load drops it, its effect on the pull
  // counted in the step. Applied to the model (LiverModel::set_surface_loads) from its next
  // step; successive calls converge. A registration step that diverges (rolled back) on loads
  // no step has yet taken without diverging (note_step) returns to the loads before them for
  // its retry (RegistrationFrame::hidden_loads_reverted). Returns hidden_load_total(). Costs
  // one solve with three columns per touched patch (J by its adjoint: A is symmetric). It is
  // apply_hidden_loads(hidden_load_fit(compliance, springs, hidden_loads())).
  double estimate_hidden_loads(StateCompliance& compliance, const std::vector<SurfaceTarget>& springs);
  // The linearised fit of that step, with `loads` as the current ones: its solves are the cost,
  // and it reads nothing a registration changes after construction (the patches), so another
  // thread may make it (the node's uncertainty worker). Empty when the estimate is off or there
  // are no springs.
  struct HiddenLoadFit {
    std::vector<int> patches;  // three columns each: the `hidden` fitted ones, then those in view that had a load
    int hidden = 0;
    Eigen::MatrixXd J;         // the touched patches' pull per unit load, weighted (sqrt w_p)
    Eigen::VectorXd r;         // their pull, weighted
    std::vector<Eigen::Vector3d> loads;  // the loads it was made with
  };
  HiddenLoadFit hidden_load_fit(StateCompliance& compliance, const std::vector<SurfaceTarget>& springs,
                                const std::vector<Eigen::Vector3d>& loads) const;
  // The step from a fit; one made with other loads than the current hidden_loads() (they were
  // reverted meanwhile) is ignored. Returns hidden_load_total().
  double apply_hidden_loads(const HiddenLoadFit& fit);
  // A step of the model outside the registration (the node's frames without a cloud): one that
  // did not diverge has taken the current hidden loads. The registration's own steps note
  // themselves.
  void note_step(const StepResult& step);
  // Per patch (SurfacePatches of options.uncertainty.patch_spacing), its hidden load (N); their
  // magnitudes' sum.
  const std::vector<Eigen::Vector3d>& hidden_loads() const { return hidden_loads_; }
  double hidden_load_total() const;

  // Per candidate: held, and the share of the springs' pull it took away when last tried.
  const std::vector<bool>& supports_held() const { return held_; }
  const std::vector<double>& support_gains() const { return gains_; }
  // The springs of the cloud alone (the model's springs also hold the held supports).
  const std::vector<SurfaceTarget>& cloud_springs() const { return cloud_springs_; }

  // Removes the springs and the hidden loads (the model relaxes at its next step), lets the
  // supports go, forgets the rigid alignment and puts the tissue's stiffness factor back to 1.
  void clear();
  // The rigid alignment applied to every cloud (identity unless options.rigid_alignment).
  const Eigen::Isometry3d& alignment() const { return alignment_; }
  const RegistrationOptions& options() const { return options_; }
  // The springs' total stiffness (N/m) from the next cloud or refinement on. Returns "" on
  // success, else the validation message (nothing changed).
  std::string set_stiffness(double stiffness);
  // The points of the last frame, after filtering and alignment (model frame, m).
  const pcl::PointCloud<pcl::PointXYZ>& points() const { return *points_; }

 private:
  // prepare_cloud into points_: the alignment, the model's box grown by max_distance.
  int filter(const pcl::PointCloud<pcl::PointXYZ>& cloud);
  void align_rigidly();
  // Correspondences at the model's current state into targets_ (the model is not touched), with
  // the frame's inlier fraction, coverage and stiffness scale; returns their number. A new
  // cloud's first update builds the locator on the triangles that face the viewpoint; later
  // ones refit it to the surface's new positions.
  int find_correspondences(bool new_cloud, const std::optional<Eigen::Vector3d>& viewpoint, RegistrationFrame& frame);
  // Why the accepted points cannot act ("" when they can).
  std::string unsupported(int accepted, double coverage) const;
  double spring_rms() const;
  // How far a surface point has moved at most since hits_ were searched (the largest node
  // motion; infinite when they are not of points_).
  double surface_motion() const;
  // Whether a point whose last hit was beyond max_distance still is after the surface moved
  // `moved` (then it need not be searched again). Points near the surface start their search
  // from their last hit's triangle.
  bool still_beyond(const SurfaceLocator::Hit& hit, double moved) const;
  // The springs' systematic pull at positions x (N^2): the sum over the surface patches of their
  // net spring force squared (the sensor's noise cancels within a patch, a model error does not).
  double systematic_pull(const std::vector<SurfaceTarget>& springs, const Eigen::VectorXd& x) const;
  // The cloud's springs plus those of the held supports, to the model.
  void apply_springs();
  // hits_ of points_ at the model's current state, on the locator as refreshed by the caller,
  // each search starting from the point's last hit if they are of points_ (those still beyond
  // max_distance are not searched).
  void search_hits();
  // RegistrationFrame::rms_all at the model's current state.
  double all_points_rms();
  // One model step with the registration's strategy and iteration cap; adds to the frame.
  void solve(RegistrationFrame& frame);
  // The last update's `found` correspondences become the cloud's springs, and are solved. A
  // solve that throws (its step rolled back) takes the springs back to those before it.
  void accept_update(int found, RegistrationFrame& frame);
  // A registered cloud's frame, completed (rms) and kept as the last.
  void finish(RegistrationFrame& frame, std::chrono::steady_clock::time_point start);
  // Up to `count` more correspondence updates of the current cloud (of options.
  // correspondence_updates), each followed by a solve (counted in frame.updates).
  void continue_updates(int count, RegistrationFrame& frame);

  LiverModel& model_;
  RegistrationOptions options_;
  Eigen::Isometry3d alignment_ = Eigen::Isometry3d::Identity();
  bool aligned_ = false;
  bool align_requested_ = false;
  pcl::PointCloud<pcl::PointXYZ>::Ptr points_, previous_points_;  // this frame's, the last accepted frame's while filtering
  std::vector<SurfaceTarget> targets_;  // of the last update
  SurfaceLocator locator_, previous_locator_;  // this cloud's, the last accepted cloud's while registering
  std::vector<SurfaceLocator::Hit> hits_, previous_hits_;  // of points_, at the positions searched_at_
  Eigen::VectorXd searched_at_, previous_searched_at_;     // empty: hits_ are not of points_
  std::optional<Eigen::Vector3d> viewpoint_;  // of the last accepted cloud (model frame)
  std::vector<std::pair<double, int>> ranked_;
  std::vector<char> covered_;  // per boundary triangle: holds an accepted point
  RegistrationFrame last_;     // of the last registered cloud (refine reports its support)
  int updates_left_ = 0;       // correspondence updates of the current cloud not yet done
  std::chrono::steady_clock::time_point frame_start_;  // of the register_cloud or refine call in progress
  std::vector<SurfaceTarget> cloud_springs_;
  struct Candidate {
    std::vector<SurfaceTarget> springs;  // point-to-point, each surface node to its rest position
    std::vector<int> nodes;
    std::vector<double> weights;  // per node, by area, summing to 1
  };
  std::vector<Candidate> supports_;
  SurfacePatches patches_;  // where the springs' pull is gathered (with candidates, the stiffness or the loads estimate)
  std::vector<bool> held_;
  std::vector<double> gains_;
  std::vector<Eigen::Vector3d> hidden_loads_;  // per patch (N)
  std::vector<Eigen::Vector3d> stepped_loads_;  // per patch (N): those of the model's last step that did not diverge
  Eigen::VectorXd shape_loads_;  // per DOF (N): those holding a one-shot registration's shape (empty: none)
  void set_model_loads();        // hidden_loads_ as nodal loads on the model, with shape_loads_
};

}  // namespace liver_sim
