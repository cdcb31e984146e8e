// How the registered model answers a force it was not told of, ROS-free: the stiffness
// A = K + the springs' stiffness at the model's current state, factorised once (CHOLMOD), and
// displacements A^-1 F for blocks of forces. The registration's analyses use it: which
// candidate supports the clouds call for (registration.h) and how far to trust each target
// (target_uncertainty.h). Static: no mass term, whatever the scene's mode.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "liver_sim/linalg/cholmod_solver.h"
#include "liver_sim/simulation/liver_model.h"

namespace liver_sim {

class StateCompliance {
 public:
  // Analyses the model's matrix pattern (once per mesh).
  explicit StateCompliance(LiverModel& model);

  // Assembles and factorises A at the model's current positions and springs. Throws
  // std::runtime_error when A is not positive definite.
  void factorize();
  // Displacements (columns, m) under forces (columns, N), zero at the supports (forces there
  // are ignored). Needs factorize().
  void solve(const Eigen::MatrixXd& forces, Eigen::MatrixXd& displacements);
  // The tissue's internal forces (N) at equilibrium(), taken as the forces applied there: at an
  // equilibrium they balance them (but for the supports' reactions), and x̄ is one to first
  // order. -A^-1 of them is how that equilibrium moves per unit log-stiffness of the tissue.
  const Eigen::VectorXd& equilibrium_internal_forces() const { return equilibrium_internal_; }
  // Where a full static solve would take the factorised state, linearised: x + A^-1 r, r the
  // out-of-balance force (the scene's loads at the model's load scale + springs + surface loads
  // + the instruments' forces below - internal forces). A registration stepped by a Newton
  // iteration or two per update is on its way there, and what the analyses read of the
  // springs' pull is the pull there.
  const Eigen::VectorXd& equilibrium() const { return equilibrium_; }
  // The forces instruments exert on the tissue at the state factorize() will take (N per DOF;
  // empty: none), counted in r as dead forces: the model handed over for an analysis has no
  // instruments (UncertaintyWorker hands over its caller's), and without them the equilibrium
  // would be the tissue's with the instruments let go.
  void set_instrument_forces(Eigen::VectorXd forces) { instrument_forces_ = std::move(forces); }
  // The positions the factor was made at.
  const Eigen::VectorXd& state() const { return state_; }
  LiverModel& model() { return model_; }

 private:
  // The scene's loads at the model's load scale, the springs, the surface loads and the
  // instruments' forces, at positions x.
  void applied_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const;

  LiverModel& model_;
  CholmodSolver factor_;
  std::vector<double> values_;
  Eigen::VectorXd state_, equilibrium_, equilibrium_internal_, instrument_forces_;
  Eigen::MatrixXd free_forces_;
};

}  // namespace liver_sim
