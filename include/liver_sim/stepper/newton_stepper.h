// The time stepper, ROS-free: static equilibrium and backward-Euler time steps by Newton's
// method on the mechanical model (mechanical_model.h), with the update strategies (Newton-Krylov,
// full and modified Newton, conjugate gradients), the predictors of dynamic steps, the line
// search, the decisions to reuse or refresh the CHOLMOD factor, the detectors that roll a
// diverging step back, and the step's wall-time budget. It owns the state (positions,
// velocities, time) and the snapshot that a rollback restores.
//
// Rollback: before each step the stepper saves everything the step may change, here, in the
// mechanical model (rotations, their warm starts, the last evaluation, the damping snapshot) and
// in the contact (instruments' poses, staging, grasps and reactions, the contacts with their
// forces, the tubes' suction loads). A step that diverges, or throws (any exception, bad_alloc
// included), restores it: the model is then the one before the step to the last bit, reactions
// included. Only the CHOLMOD factor is not copied (its size is the factor's): a rolled-back step
// that refactorised leaves it to be refactorised at the next step.
//
// Time budget (SolverOptions::time_budget): past it, a step stops before the next Newton
// iteration or instrument stage, NotConverged ("time budget"), and keeps the iterate, judged as
// the iteration cap judges it (a stall rolls back). Every iterate is a state Newton would go on
// from: finite, below the blow-up bound, its contacts detected, accepted by the line search
// (merit or potential fell); the next step continues the same solve. Going back to the last good
// state instead would repeat the same frame for ever when one iteration (or one rising-merit
// iteration of a real-time frame) does not fit in the budget. Out of time between stages, the
// instruments stay at the last stage's pose and the next step stages on from there.
//
// It asks the contact (instrument_contact.h) for the contact forces, violation and constrained
// update, and hands it its factor; it may not look inside the element sets or the contact rows.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCholesky>
#include <chrono>
#include <limits>
#include <memory>
#include <string>

#include "liver_sim/linalg/background_factorization.h"
#include "liver_sim/linalg/cholmod_solver.h"
#include "liver_sim/linalg/conjugate_gradient.h"
#include "liver_sim/linalg/gmres.h"
#include "liver_sim/contact/instrument_contact.h"
#include "liver_sim/model/mechanical_model.h"

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
  StepTiming timing;
  std::string message;      // why, when not converged
  bool converged() const { return status == Status::Converged; }
};

class NewtonStepper {
 public:
  // Analyses the matrix pattern (CHOLMOD). Throws std::invalid_argument for invalid options.
  NewtonStepper(MechanicalModel& mechanics, InstrumentContact& contact, const SolverOptions& solver);

  // Static mode: Newton to equilibrium under the loads times load_scale(). Dynamic mode: one
  // backward-Euler time step of solver.dt. Both advance time() by solver.dt (in static mode a
  // pseudo-time that drives the instruments' trajectories). A diverging step restores the
  // state before it.
  StepResult step();

  // Static load continuation: loads are multiplied by this factor (default 1).
  void set_load_scale(double s) { load_scale_ = s; }
  double load_scale() const { return load_scale_; }

  const SolverOptions& options() const { return solver_; }
  // Strategy, iteration cap, tolerance, line search, dt and damping, from the next step on. The
  // mode and the threads cannot change. Returns "" on success, else the validation message
  // (nothing changed).
  std::string set_options(const SolverOptions& solver);

  const Eigen::VectorXd& positions() const { return x_; }  // 3 #V, node-major (m)
  // Overwrites the current state (tests start from a given configuration).
  void set_positions(const Eigen::VectorXd& x);
  const Eigen::VectorXd& step_start() const { return x_start_; }  // positions the last step started from
  double time() const { return time_; }

  // The mechanical model changed other than through the state (material, capsule, springs):
  // the energy known for the state is void and, with refactorize, the factor too.
  void model_changed(bool refactorize);
  // The next Newton iteration factorises the matrix afresh.
  void refactorize() { drop_factor(); }
  // Back to the rest shape, zero velocity, time 0.
  void reset();

  const Eigen::VectorXd& velocities() const { return v_; }  // 3 #V (m/s), dynamic mode

  // The state before the last step, restored (the node's barrier uses it for a step whose result
  // it cannot use). Valid right after a step; false, and nothing changed, when there is none (no
  // step since construction, reset(), set_positions() or model_changed()).
  bool undo_step();

  // Test hook: a fault the next step meets on purpose, so that the tests, the stress matrix and
  // the node's soak (~test_fault_every) exercise the rollback. Not for use in operation.
  enum class InjectedFault {
    None,
    Exception,           // std::runtime_error after the step's first Newton update
    OutOfMemory,         // std::bad_alloc there
    NonFinite,           // a NaN in the first Newton update: the non-finite detector fires
    NotPositiveDefinite,  // the step's first CHOLMOD factorisation gets a negative pivot: the
                          // definiteness detector fires (strategies that factorise with CHOLMOD)
    Slow                  // the step's first Newton update held up for kInjectedDelay: a frame
                          // far beyond its time budget, nothing to roll back (the node's
                          // heartbeat must keep ~status going meanwhile)
  };
  static constexpr std::chrono::milliseconds kInjectedDelay{300};
  void inject_fault(InjectedFault f) { fault_ = f; }
  // Steps held up by an injected Slow fault since construction (the soak leaves that time out of
  // the frame rate it judges).
  long held_up_on_purpose() const { return held_up_on_purpose_; }

  // Force the supports exert on the tissue at the fixed DOFs (N; 0 elsewhere).
  Eigen::VectorXd support_forces();
  CholmodSolver& linear_solver() { return cholmod_; }

 private:
  // Residual r = loads - internal - inertia - damping + contact at x (dynamic terms use x_start_,
  // v_). Returns its free-DOF norm and the reference norm it is measured against. With
  // zero_fixed = false the entries at fixed DOFs are kept: minus the constraint forces.
  double residual(const Eigen::VectorXd& x, Eigen::VectorXd& r, double* reference, bool zero_fixed = true);
  // Line-search merit: the free residual norm and the contact violation, in newtons.
  double merit(double residual_norm, const Eigen::VectorXd& x) const;
  // Whether a factorisation as long as the last one would end before the step's deadline.
  bool factorization_fits() const;
  // The strategy of the next iteration, and whether that iteration starts with a factorisation.
  SolverOptions::Strategy iteration_strategy() const;
  bool factorizes(SolverOptions::Strategy strategy) const;
  // Newton iterations from the current state; adds to result (iterations, timings, status).
  // contacts_detected: the contacts are already those of the current state. Past the time
  // budget it stops.
  void newton(StepResult& result, bool contacts_detected);
  // Dynamic steps: the mechanical energy (kinetic + elastic) and the work of the loads and of
  // the constraints over the step that ended at x_ (J).
  double mechanical_energy(const Eigen::VectorXd& x, const Eigen::VectorXd& v);
  double work_over_step();
  // The Newton matrix into system_ with the element rotations of the last residual() call: the
  // solver always assembles where it last evaluated.
  void assemble_system();
  // step() without the exception barrier.
  StepResult advance();
  // The factor no longer fits the model: the next iteration factorises in the step, and a
  // background factorisation in progress is not taken up.
  void drop_factor();
  // SolverOptions::background_refresh: the thread and its solver's analysis, once, when the
  // option is first on (at construction or in set_options, not in a step).
  void make_background();
  // At the start of an iteration: a finished background factor replaces the one in use; a
  // wanted one starts from the state last evaluated, if the thread is free.
  void refresh_in_background(StepResult& result);
  // True once when the injected fault is f (it is then consumed).
  bool take_fault(InjectedFault f);

  struct Snapshot {
    Eigen::VectorXd x, v, v_previous, x_start;
    double time = 0, state_energy = 0;
    bool rotations_continued = false, factor_valid = false, refresh_wanted = false;
    long factorizations = 0;  // factorizations_ when taken
    long background_starts = 0;  // background_starts_ when taken
    MechanicalModel::EvaluationState mechanics;
    InstrumentContact::State contact;
  };
  void save(Snapshot& s);
  void restore(const Snapshot& s);
  Snapshot snapshot_;
  bool snapshot_valid_ = false;
  long factorizations_ = 0;  // CHOLMOD factorisations since construction
  InjectedFault fault_ = InjectedFault::None;
  long held_up_on_purpose_ = 0;
  std::chrono::steady_clock::time_point deadline_;  // of the step in progress (time_budget)
  std::chrono::steady_clock::duration factorization_time_{};  // of the last CHOLMOD factorisation

  MechanicalModel& mechanics_;
  InstrumentContact& contact_;
  SolverOptions solver_;
  std::vector<double> system_;
  bool factor_valid_ = false;  // the factor preconditions the current constraint set and material
  bool refresh_wanted_ = false;  // background refresh: the factor serves, a fresh one is asked for
  CholmodSolver cholmod_;
  std::unique_ptr<BackgroundFactorization> background_;  // while SolverOptions::background_refresh was ever on
  long background_starts_ = 0;  // background factorisations started since construction
  Gmres gmres_;
  ConjugateGradient cg_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Upper> eigen_ldlt_;
  bool eigen_analyzed_ = false;
  Eigen::VectorXd jacobi_;  // inverse diagonal of system_ (CG strategy)

  Eigen::VectorXd x_, v_, x_start_;
  Eigen::VectorXd v_previous_;  // velocity of the step before the last (the predictor's acceleration)
  bool rotations_continued_ = false;  // the last step predicted the rotations and was accepted
  double load_scale_ = 1.0;
  double state_energy_ = std::numeric_limits<double>::quiet_NaN();  // J, of (x_, v_) when known
  double time_ = 0.0;

  // Work vectors kept between steps (no allocation per step).
  Eigen::VectorXd r_, r_try_, dx_, x_try_, f_tmp_, v_tmp_, f_ext_, energy_work_;
};

}  // namespace liver_sim
