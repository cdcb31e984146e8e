// How far to trust each tracked target after registration, ROS-free: a linearised sensitivity
// of the registered targets to what the model does not know, as a 3 x 3 covariance per target.
//
// The registered state minimises the tissue's energy plus the springs' (registration.h). Near
// it, a force f the model was not told of moves the state by A^-1 f, A = K + the springs'
// stiffness (the surface the camera sees is held by the cloud, the rest is free), and a target
// t = J x (its barycentric embedding) by J A^-1 f. Three unknowns are propagated, independent:
//   - forces on the surface: a retractor under a lobe, a ligament's reaction, the diaphragm,
//     another organ. One force per patch of the boundary (patches `patch_spacing` apart, each
//     spread as a Gaussian bump of width patch_spacing / 2), independent, of standard deviation
//     `force_ratio` times the typical force the cloud's springs exert on a patch, in every
//     direction: the cloud shows how hard the surgery pulls on what is seen; as much may act
//     on any patch. The pull is taken without the model's surface loads (the hidden loads the
//     registration found, linearised), which carry part of it;
//   - the tissue's stiffness, a factor exp(s), s ~ N(0, stiffness_log_sd^2): the state moves by
//     -A^-1 f_int s (f_int: the tissue's internal forces at the equilibrium the state is on
//     its way to, StateCompliance::equilibrium);
//   - the sensor: each spring's point moves along its normal by the springs' RMS length.
// Cost: with A factorised (state_compliance.h), one solve with 3 right-hand sides per target and
// products over the patches' nodes. Options: RegistrationOptions::uncertainty (options.h).
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <vector>

#include "liver_sim/model/embedded_vessels.h"
#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/registration/state_compliance.h"
#include "liver_sim/registration/surface_patches.h"

namespace liver_sim {

// The 0.95 quantile of the chi-square distribution with 3 degrees of freedom: an error e lies in
// the 95% ellipsoid of covariance C when e^T C^-1 e is at most this.
constexpr double kChiSquare3At95 = 7.814727903251178;
// The 95% ellipsoid of a covariance (m^2): semi-axes (m, ascending) along the columns of `axes`
// (a rotation).
struct Ellipsoid {
  Eigen::Vector3d semi_axes;
  Eigen::Matrix3d axes;
};
Ellipsoid ellipsoid_95(const Eigen::Matrix3d& covariance);

// Each point's tetrahedron of T at positions x: the one that holds it best (largest smallest
// barycentric weight; a point outside the mesh gets the nearest by that measure).
std::vector<EmbeddedPoint> embed_points(const Eigen::MatrixX4i& T, const Eigen::VectorXd& x,
                                        const std::vector<Eigen::Vector3d>& points);

class TargetUncertainty {
 public:
  // Embeds tracked_targets(model) in the tetrahedra of the model's current positions (the
  // embedding is material: it holds at any later state) and places the patches on its rest
  // shape. Throws std::invalid_argument for invalid options.
  TargetUncertainty(LiverModel& model, const UncertaintyOptions& options);

  // Covariances (m^2) of tracked_targets(model), in its order, at the state `compliance` was
  // factorised at, with the model's surface loads: the total and its three parts.
  // `cloud_springs`: the springs of the cloud (SurfaceRegistration::cloud_springs), whose forces
  // scale the unknown ones and whose lengths are the noise, both read at the equilibrium that
  // state is on its way to (StateCompliance::equilibrium).
  struct Covariance {
    Eigen::Matrix3d total, forces, stiffness, noise;
  };
  std::vector<Covariance> covariances(StateCompliance& compliance, const std::vector<SurfaceTarget>& cloud_springs);

  // A target's position from node positions x through the embedding (m).
  Eigen::Vector3d position(int target, const Eigen::VectorXd& x) const;
  int num_targets() const { return static_cast<int>(embedding_.size()); }
  // The unit patch forces: 3 columns (x, y, z) per patch, one row per DOF.
  const Eigen::SparseMatrix<double>& patch_forces() const { return patch_forces_; }
  // The typical spring force per patch (N) of the last covariances() call.
  double typical_patch_force() const { return typical_force_; }

 private:
  LiverModel& model_;
  UncertaintyOptions options_;
  std::vector<EmbeddedPoint> embedding_;
  SurfacePatches patches_;
  Eigen::SparseMatrix<double> patch_forces_;
  double typical_force_ = 0;
};

}  // namespace liver_sim
