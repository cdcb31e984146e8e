// How a Newton iteration computes its update and when the factor is refreshed: the variation
// point of the stepper (SolverOptions::Strategy, doc/performance.md). One type per strategy, each
// in a file of its own; make_update_strategy is the table from a strategy to its type. The
// Newton loop (newton_stepper.cpp) asks a strategy these questions in this order and knows none
// by name:
//
//   with_contacts()            which strategy iterates while instruments touch: this one, when
//                              its solve carries the contact forces, else another that does
//   begin_iteration()          a background factor taken up or started
//   factorizes()               the iteration starts with a CHOLMOD factorisation (the time
//                              budget asks before it starts; the loop assembles and factorises)
//   current_tangent()          the matrix is assembled at the iterate even without one
//   prepare()                  a factorisation of its own, after the assembly
//   solve()                    the update dx for the residual
//   scales_contact_forces()    a line search's trial point carries that share of the contact
//                              force change the update made
//   redoes_without_descent()   an iteration on an old factor that finds no descent is redone on
//                              a fresh one, once per Newton solve
//   end_iteration()            after an accepted iteration: the factor judged
#pragma once

#include <Eigen/Core>
#include <memory>

#include "liver_sim/contact/instrument_contact.h"
#include "liver_sim/linalg/gmres.h"
#include "liver_sim/model/mechanical_model.h"
#include "liver_sim/stepper/newton_matrix.h"
#include "liver_sim/stepper/step_result.h"
#include "liver_sim/stepper/tangent_factor.h"
#include "wall_time.h"

namespace liver_sim {

constexpr int kMaxKrylov = 30;      // Krylov iterations per Newton update (GMRES, preconditioned CG)
constexpr int kRefactorAfter = 10;  // Krylov iterations beyond which the factor preconditions poorly

// What the strategies work with: the stepper's, for its lifetime.
struct StrategyParts {
  MechanicalModel& mechanics;
  InstrumentContact& contact;
  NewtonMatrix& matrix;   // assembled for the iteration when factorizes() or current_tangent()
  TangentFactor& factor;
  const SolverOptions& solver;  // the stepper's current options
};

// One Newton iteration's system: J dx = r.
struct NewtonIteration {
  const Eigen::VectorXd& r;          // residual at the iterate (N; free forces and contact forces, 0 at fixed DOFs)
  double forcing;                    // relative tolerance of an iterative solve
  double force_tolerance;            // N: the contact problem's share of the residual the step must reach
  const Gmres::Operator& jacobian;   // products with the true Jacobian (directional differences of the residual)
  StepResult& result;                // the work's counters and times
  // The step's time budget: an iterative solve stops there with its iterate so far, and the
  // Newton loop judges the iteration's end as out of time.
  Gmres::Clock::time_point deadline;
};

// An accepted iteration, for the strategy to judge its factor by.
struct IterationEnd {
  const Eigen::VectorXd& r_start;  // residual where the iteration started
  double start_norm;               // its norm, and the norm where it ended (N)
  double end_norm;
  bool fresh_factor;               // the iteration started with a factorisation
  bool contact_forces_scaled;      // its update changed the contact forces (scales_contact_forces, with contacts)
};

class UpdateStrategy {
 public:
  explicit UpdateStrategy(const StrategyParts& parts) : parts_(parts) {}
  virtual ~UpdateStrategy() = default;
  UpdateStrategy(const UpdateStrategy&) = delete;
  UpdateStrategy& operator=(const UpdateStrategy&) = delete;

  // With instrument contacts, the strategy whose iterations carry them: the strategies that
  // solve with the factor carry the contact forces in the same solve; the others hand their
  // iterations to Newton-Krylov, which has the factor too.
  virtual SolverOptions::Strategy with_contacts() const { return SolverOptions::Strategy::NewtonKrylov; }
  // A refresh finished in the background taken up, one wanted started (background_refresh).
  virtual void begin_iteration(StepResult& result);
  virtual bool factorizes() const = 0;
  virtual bool current_tangent() const = 0;
  // False when the matrix is not positive definite (the step rolls back).
  virtual bool prepare(StepResult&) { return true; }
  // dx for it.r; returns the Krylov iterations it took (0 for a direct solve).
  virtual int solve(const NewtonIteration& it, Eigen::VectorXd& dx) = 0;
  virtual bool scales_contact_forces() const { return false; }
  virtual bool redoes_without_descent() const { return false; }
  virtual void end_iteration(const IterationEnd&) {}

 protected:
  // dx = A^-1 r with the factor; with contacts, the direct contact update: the contact forces
  // in the same solve.
  int direct_solve(const NewtonIteration& it, Eigen::VectorXd& dx);
  // A factor that preconditions an iterative solve poorly (many iterations, or the solve not
  // reaching its tolerance) is refreshed at the next iteration. A solve stopped at the deadline
  // is judged by its iterations only: its residual says when it stopped, not how it converged.
  void judge_preconditioner(int iterations, double relative_residual, double forcing, bool out_of_time);
  // The factor no longer serves well: refactorised in the step, or with background_refresh on
  // a thread of its own while it serves meanwhile.
  void refresh();
  StrategyParts parts_;
};

// The strategy's type. Throws std::bad_alloc.
std::unique_ptr<UpdateStrategy> make_update_strategy(SolverOptions::Strategy strategy, const StrategyParts& parts);

}  // namespace liver_sim
