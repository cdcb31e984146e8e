#include "liver_sim/registration/state_compliance.h"

#include <stdexcept>

namespace liver_sim {

StateCompliance::StateCompliance(LiverModel& model) : model_(model) {
  const SparsePattern& pattern = model.mechanics().pattern();
  factor_.analyze(pattern.rows(), pattern.column_start(), pattern.row_index());
}

void StateCompliance::factorize() {
  MechanicalModel& m = model_.mechanics();
  state_ = model_.positions();
  Eigen::VectorXd internal;
  m.internal_forces(state_, internal);  // also the element rotations the tangent is taken at
  m.assemble(1.0, 0.0, values_);
  if (!factor_.factorize(values_))
    throw std::runtime_error("the registered model's stiffness is not positive definite");
  Eigen::VectorXd out_of_balance;
  applied_forces(state_, out_of_balance);
  out_of_balance -= internal;
  Eigen::MatrixXd way;
  solve(out_of_balance, way);  // zero at the supports
  equilibrium_ = state_ + way.col(0);
  applied_forces(equilibrium_, equilibrium_internal_);
}

void StateCompliance::applied_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const {
  const MechanicalModel& m = model_.mechanics();
  m.external_forces(x, f);
  f *= model_.load_scale();
  m.add_target_forces(x, f);  // the springs and the surface loads
  if (instrument_forces_.size() == f.size()) f += instrument_forces_;
}

void StateCompliance::solve(const Eigen::MatrixXd& forces, Eigen::MatrixXd& displacements) {
  // A has identity rows and columns at the supports: zero forces there give zero displacements.
  free_forces_ = forces;
  const std::vector<char>& fixed = model_.mechanics().fixed_dofs();
  for (int i = 0; i < free_forces_.rows(); ++i)
    if (fixed[i]) free_forces_.row(i).setZero();
  factor_.solve(free_forces_, displacements);
}

}  // namespace liver_sim
