// One-shot registration of the liver model to one cloud of an organ already deformed by several
// centimetres, its attachments unknown, ROS-free: how a navigation system is first registered.
// The tracker (registration.h) then follows the organ from frame to frame.
//
// The unknowns are the rigid motion between the model's frame and the cloud's, and the forces
// on the organ's surface that deform it (a force per surface patch, patch_spacing apart, each a
// Gaussian bump as in surface_patches.h, on every patch: the surgery's forces and the unknown
// attachments' reactions alike). The scene's supports are not held rigidly (they are a guess
// the cloud may contradict): a weak elastic foundation on the whole surface (the surrounding
// organs) holds the model where no force acts, stiffer where the scene's supports are (so that
// a view of part of the organ does not let the part it does not show drift); the rigid motion
// is the cloud's, not the model's, so the foundation does not resist it.
//
// 1. Rigid initialisation: point-to-plane ICP of the cloud to the rest shape's surface, exact
//    closest points on the triangles within a gate that shrinks from start_gate to end_gate,
//    normals in the correspondence (a point and a triangle facing apart more than
//    max_normal_angle do not correspond), the farthest trim_fraction dropped, Huber weights.
// 2. Deformation, in rounds: the model's tangent stiffness A (with the foundation) is
//    factorised at its current equilibrium and the patches' unit forces solved once (B = A^-1
//    Phi, three columns per patch); within a round the surface moves as x + B dg (linearised),
//    and each correspondence update solves a damped Gauss-Newton step for the loads and the
//    rigid motion together: minimise sum_i w_i (n_i . (x_i - p_i))^2 + lambda |g|^2, lambda =
//    damping x the mean diagonal of the loads' normal matrix, the damping falling from
//    start_damping to load_damping and the gate from start_gate to end_gate over the rounds
//    (continuation: the coarse, stiff shape first). After each round the loads act on the
//    nonlinear (corotational) model, which is solved to equilibrium, and the next round
//    linearises there.
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "liver_sim/geometry/mesh.h"
#include "liver_sim/geometry/surface_locator.h"
#include "liver_sim/model/embedded_vessels.h"
#include "liver_sim/registration/state_compliance.h"
#include "liver_sim/registration/surface_patches.h"
#include "liver_sim/scene/scene.h"
#include "liver_sim/simulation/liver_model.h"

namespace liver_sim {

struct OneShotOptions {
  double voxel_size = 4e-3;        // m, in [0, 0.1]: the cloud's voxel grid (cloud_filter.h)
  int max_points = 4000;           // in [50, 100000]: points kept after it (even stride beyond)
  int normal_neighbours = 12;      // in [4, 100]: points whose spread gives a point's normal
  double start_gate = 0.05;        // m, in (0, 1]: correspondences at the start (the largest motion sought)
  double end_gate = 0.01;          // m, in (0, start_gate]: at the end
  double max_normal_angle = 1.05;  // rad, in (0, pi]: a point and a triangle whose normals differ more do not correspond
  double trim_fraction = 0.1;      // -, in [0, 0.9): the farthest share of the gated points is dropped
  double huber_width = 2e-3;       // m, > 0: beyond it a point weighs width / distance
  int rigid_iterations = 30;       // in [0, 1000]: ICP iterations (0: the start pose stands)
  double patch_spacing = 0.04;     // m, in [1e-3, 1]: between the centres of the load patches
  double start_damping = 0.1;      // -, in [load_damping, 1e3]: the loads' Tikhonov weight at the start
  double load_damping = 3e-3;      // -, in [1e-9, 1e3]: at the end, over the mean diagonal of the normal matrix
  double foundation = 0.1;         // -, in (0, 10]: the foundation's stiffness per area over E / L (E the
                                   // parenchyma's Young's modulus, L the cube root of the volume)
  double support = 3.0;            // -, in [0, 1e3]: besides, the scene's supports (the surface nodes inside its
                                   // fixed regions) held by springs of this stiffness per area over E / L (0: free)
  int rounds = 2;                  // in [1, 20]: linearisations
  int iterations = 6;              // in [1, 100]: correspondence updates per round
  // The targets' uncertainty (OneShotRegistration::uncertainty); chosen on the in-silico case's
  // views xy and xz-hemi (doc/registration.md).
  double posterior_scale = 1.5;    // -, >= 0: on the fit's posterior standard deviations
  double damping_error = 0.0;      // -, >= 0: the model's error per axis over a point's motion per unit log of the damping
  double displacement_error = 0.03;  // -, in [0, 1]: the model's error per axis over the point's displacement
  double model_error_floor = 5e-5; // m, >= 0: and an error of this much everywhere
};
// Empty when valid, else a message naming the field at fault ("one_shot.<field>").
std::string validate(const OneShotOptions& o);

struct OneShotResult {
  Eigen::Isometry3d alignment = Eigen::Isometry3d::Identity();  // the cloud's frame -> the model's
  Eigen::Isometry3d rigid_alignment = Eigen::Isometry3d::Identity();  // the same after the rigid stage alone
  Eigen::VectorXd positions;                 // m: the registered shape, model frame
  std::vector<Eigen::Vector3d> patch_loads;  // N, per load patch
  int input_points = 0;     // finite points received
  int used_points = 0;      // after the voxel grid
  int correspondences = 0;  // accepted at the end
  double coverage = 0;      // share of the boundary area on triangles holding an accepted point
  double rigid_rms = 0;     // m: the accepted points' distance to the surface after the rigid stage
  double rms = 0;           // m: at the end
  double load_total = 0;    // N: the sum of the patch loads' magnitudes
  double filter_ms = 0, rigid_ms = 0, deform_ms = 0, total_ms = 0;
};

class OneShotRegistration {
 public:
  // Builds a model of its own from `mesh` and `scene` without its supports, instruments or scene
  // loads, held by the foundation (stiffer on the supports). Throws std::invalid_argument for invalid options or a
  // scene the model refuses.
  OneShotRegistration(const TetMesh& mesh, const Scene& scene, const OneShotOptions& options);

  // The shape the solve starts from, model frame: the rest shape unless set. A tracking session
  // gives its model's state (the pre-operative equilibrium under gravity and supports, an
  // instrument's press), held by constant loads (its internal forces) on the free model, the
  // foundation anchored there: the fitted loads act on top of what the scene already explains.
  void set_reference(const Eigen::VectorXd& positions);

  // Registers the reference shape to `cloud` (its own frame; `start`: a first guess of its
  // transform into the model's frame), seen from `viewpoint` (the sensor's origin in the
  // cloud's frame) when known. Throws std::invalid_argument when no finite point lies within
  // start_gate of the model, or fewer than 50 points correspond.
  OneShotResult solve(const pcl::PointCloud<pcl::PointXYZ>& cloud,
                      const std::optional<Eigen::Vector3d>& viewpoint = std::nullopt,
                      const Eigen::Isometry3d& start = Eigen::Isometry3d::Identity());

  // How far to trust points embedded in the mesh after the last solve(): per point, a 3 x 3
  // covariance (m^2, the cloud's frame) of its registered position, the sum of
  //   - the fit's own uncertainty, linearised: the loads and the rigid motion have the posterior
  //     of the damped least squares read as Bayesian (the points' residuals independent, of the
  //     variance their weighted residuals show, the loads a priori independent, of the fitted
  //     ones' square sum over the number of loads the cloud determines), propagated through the
  //     last round's B and the embedding, times posterior_scale squared;
  //   - the model's form (the material, the foundation, the loads' shapes are guesses, and the
  //     damping pulls the loads towards zero where the cloud says little): isotropic, of
  //     variance model_error_floor^2 + (damping_error x the point's motion per unit log of the
  //     damping)^2 + (displacement_error x the point's displacement)^2.
  // The point's registered position rides with it (`positions`, cloud frame).
  struct PointUncertainty {
    Eigen::Vector3d position;    // m, cloud frame
    Eigen::Vector3d displacement;  // m: by the loads (the registered shape less the reference shape)
    Eigen::Matrix3d fit, model;    // m^2: the two parts
    Eigen::Vector3d prior;         // m: its motion per unit log of the damping
    Eigen::Matrix3d total() const { return fit + model; }
  };
  std::vector<PointUncertainty> uncertainty(const std::vector<EmbeddedPoint>& points) const;

  const OneShotOptions& options() const { return options_; }
  LiverModel& model() { return *model_; }

 private:
  struct Match {
    int point;
    SurfaceLocator::Hit hit;
    double weight;
  };
  // Correspondences of the points moved by `alignment` to the surface at positions y, within
  // `gate`, trimmed and weighted; with `same_side`, only those whose normals agree within
  // max_normal_angle.
  std::vector<Match> match(const Eigen::VectorXd& y, const Eigen::Isometry3d& alignment, double gate, bool same_side = true);
  void rigid_stage(OneShotResult& result);
  void deformation_stage(OneShotResult& result);
  // Newton iterations of the free model under its loads.
  void settle(int iterations);
  double schedule(double start, double end, double t) const;

  OneShotOptions options_;
  std::unique_ptr<LiverModel> model_;
  StateCompliance compliance_;
  SurfacePatches patches_;
  Eigen::MatrixXd unit_loads_;  // Phi: 3 columns per patch
  SurfaceLocator locator_;
  pcl::PointCloud<pcl::PointXYZ> points_;  // the cloud after filtering, its own frame
  std::vector<Eigen::Vector3d> normals_;   // theirs, same frame
  Eigen::Isometry3d alignment_ = Eigen::Isometry3d::Identity();
  Eigen::VectorXd reference_;         // m: the start shape (set_reference)
  Eigen::VectorXd reference_loads_;   // N: the constant loads that hold it
  Eigen::VectorXd loads_;  // per patch, stacked (N)
  // The last round's linearisation, for uncertainty(): B, the normal matrix with its damping,
  // the residuals' variance, the centre of the rigid steps.
  Eigen::MatrixXd basis_, normal_;
  double residual_variance_ = 0, damping_ = 0;
  Eigen::Vector3d centre_ = Eigen::Vector3d::Zero();
};

}  // namespace liver_sim
