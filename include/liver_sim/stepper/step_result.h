// What one step of the stepper reports: how it ended, the work it did and its wall time by
// phase. Plain data, ROS-free.
#pragma once

#include <string>

namespace liver_sim {

// Wall time of one step by phase (ms).
struct StepTiming {
  double assembly_ms = 0;       // rotation update, internal/external forces, tangent assembly
  double factorization_ms = 0;  // CHOLMOD numeric factorisations
  double solve_ms = 0;          // GMRES: triangular solves and Jacobian products
  double contact_ms = 0;        // detection, compliance columns, Delassus operator, Gauss-Seidel
  double total_ms = 0;
};

struct StepResult {
  enum class Status {
    Converged,     // residual below tolerance
    NotConverged,  // iteration cap reached closer to equilibrium; the state is kept (the next step
                   // continues from it)
    Diverged       // rolled back: non-finite values, a tangent that is not positive definite, a
                   // residual blow-up, a stall (the cap reached no closer to equilibrium than the
                   // step started), or (dynamic) mechanical energy growing beyond the work done
  };
  Status status = Status::Converged;
  int iterations = 0;         // Newton iterations (factorisations) in this step
  int linear_iterations = 0;  // GMRES iterations (preconditioned solves) in this step
  int factorizations = 0;     // numeric factorisations in this step (often 0: the factor is reused)
  int background_factorizations = 0;  // factors finished on the background thread and taken up
                                      // in this step (SolverOptions::background_refresh)
  int contacts = 0;           // instrument contacts carrying force at the end of the step
  int contact_sweeps = 0;     // Gauss-Seidel sweeps of the contact solves in this step
  double residual = 0;      // force residual relative to the load norm, at the end
  bool out_of_time = false;  // the step stopped at SolverOptions::time_budget
  bool recovery = false;     // after steps rolled back in a row, solved past the frame's iteration
                             // cap and time budget (NewtonStepper::kRecoveryAfterRollbacks)
  bool past_cap = false;     // far from equilibrium at its iteration cap, an iteration past the
                             // cap taken within its time budget (SolverOptions::capped_residual)
  StepTiming timing;
  std::string message;      // why, when not converged
  bool converged() const { return status == Status::Converged; }
};

}  // namespace liver_sim
