// The matrix of the stepper's Newton iterations, ROS-free: A = K in static mode, A = (1 + b/dt) K
// + (1/dt^2 + a/dt) M for a backward-Euler step (Rayleigh damping D = a M + b K), on the model's
// fixed pattern (upper triangle, the layout CHOLMOD reads). Assembled with the element rotations
// of the model's last evaluation: the solver always assembles where it last evaluated.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "liver_sim/model/mechanical_model.h"

namespace liver_sim {

struct StepTiming;

class NewtonMatrix {
 public:
  // solver: the stepper's options, read at each assembly (mode, dt, damping).
  NewtonMatrix(MechanicalModel& mechanics, const SolverOptions& solver);

  // A at the model's last evaluation; its wall time is added to timing.assembly_ms.
  void assemble(StepTiming& timing);
  const SparsePattern& pattern() const { return mechanics_.pattern(); }
  const std::vector<double>& values() const { return values_; }
  std::vector<double>& values() { return values_; }
  // out = A v.
  void multiply(const Eigen::VectorXd& v, Eigen::VectorXd& out) const { pattern().multiply(values_, v, out); }

 private:
  MechanicalModel& mechanics_;
  const SolverOptions& solver_;
  std::vector<double> values_;
};

}  // namespace liver_sim
