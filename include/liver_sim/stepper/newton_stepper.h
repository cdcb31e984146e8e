// The time stepper, ROS-free: static equilibrium and backward-Euler time steps by Newton's
// method on the mechanical model (mechanical_model.h): the predictors of dynamic steps, the
// Newton loop with its line search, the detectors that roll a diverging step back, and the
// step's wall-time budget. How an iteration computes its update and when the factor
// (tangent_factor.h) is refreshed is the update strategy's (src/core/stepper/update_strategy.h:
// Newton-Krylov, full and modified Newton, conjugate gradients, one type each). It owns the
// state (positions, velocities, time) and the snapshot that a rollback restores.
//
// Rollback: before each step the stepper saves everything the step may change, here, in the
// mechanical model (rotations, their warm starts, the last evaluation, the damping snapshot) and
// in the contact (instruments' poses, staging, grasps and reactions, the contacts with their
// forces, the tubes' suction loads). A step that diverges, or throws (any exception, bad_alloc
// included), restores it: the model is then the one before the step to the last bit, reactions
// included. Only the CHOLMOD factor is not copied (its size is the factor's): a rolled-back step
// that refactorised leaves it to be refactorised at the next step.
//
// Recovery: after kRecoveryAfterRollbacks steps in a row diverged (a detector fired; a step
// that throws is rolled back but not counted), a step is solved with kRecoveryIterations
// iterations at least and kRecoveryBudgets time budgets. A real-time frame's cap and budget,
// met again from the state they diverged from, with the instruments as far on or farther, can
// diverge again frame after frame while the instruments move on: the model frozen (bench, the
// phantom with a probe pressing and sweeping under breathing loads: 163-281 of 300 frames rolled
// back; doc/robustness.md#recovery). One frame runs late instead; if it diverges too, the count
// starts again.
//
// Time budget (SolverOptions::time_budget): past it, a step stops before the next Newton
// iteration or instrument stage, NotConverged ("time budget"), and keeps the iterate, judged as
// the iteration cap judges it (a stall rolls back). Every iterate is a state Newton would go on
// from: finite, below the blow-up bound, its contacts detected, accepted by the line search
// (merit or potential fell); the next step continues the same solve. Going back to the last good
// state instead would repeat the same frame for ever when one iteration (or one rising-merit
// iteration of a real-time frame) does not fit in the budget. Out of time between stages, the
// instruments stay at the last stage's pose and the next step stages on from there.
// With a budget, a frame that reaches its iteration cap with its residual above
// SolverOptions::capped_residual iterates on, to kRecoveryIterations in the step, and no
// iteration past the cap (its factorisation included) runs beyond kDriftBudgetShare of the
// budget: a frame ended that far off starts the next one farther off, until a surface point ends
// inside an instrument (the phantom's probe sweep at 33 ms frames, two iterations each: 4.6%
// error, 114% at 1/30 s; doc/robustness.md#frames-far-from-equilibrium). The rest of the budget
// is the frame's other work (a cloud's registration, the publication): a step that took all of it
// cost the node's soak 2-3 frames a second. Without a budget the cap is the frame's cost.
//
// It asks the contact (instrument_contact.h) for the contact forces, violation and constrained
// update, and hands it its factor; it may not look inside the element sets or the contact rows.
#pragma once

#include <Eigen/Core>
#include <chrono>
#include <limits>
#include <map>
#include <memory>
#include <string>

#include "liver_sim/contact/instrument_contact.h"
#include "liver_sim/linalg/cholmod_solver.h"
#include "liver_sim/model/mechanical_model.h"
#include "liver_sim/stepper/newton_matrix.h"
#include "liver_sim/stepper/step_result.h"
#include "liver_sim/stepper/tangent_factor.h"

namespace liver_sim {

class UpdateStrategy;

class NewtonStepper {
 public:
  // Recovery (above): after how many rollbacks in a row, with how many iterations at least and
  // how many time budgets.
  static constexpr int kRecoveryAfterRollbacks = 2;
  static constexpr int kRecoveryIterations = 50;
  static constexpr int kRecoveryBudgets = 10;
  // Frames far from equilibrium (above): the share of the time budget, from the step's start,
  // within which they iterate on.
  static constexpr double kDriftBudgetShare = 0.5;

  // Analyses the matrix pattern (CHOLMOD). Throws std::invalid_argument for invalid options.
  NewtonStepper(MechanicalModel& mechanics, InstrumentContact& contact, const SolverOptions& solver);
  ~NewtonStepper();

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
  void refactorize() { factor_.drop(); }
  // The processors of the background refreshes (TangentFactor::place_background).
  std::string place_background(std::vector<int> cpus) { return factor_.place_background(std::move(cpus)); }
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
  CholmodSolver& linear_solver() { return factor_.solver(); }

 private:
  // Residual r = loads - internal - inertia - damping + contact at x (dynamic terms use x_start_,
  // v_). Returns its free-DOF norm and the reference norm it is measured against. With
  // zero_fixed = false the entries at fixed DOFs are kept: minus the constraint forces.
  double residual(const Eigen::VectorXd& x, Eigen::VectorXd& r, double* reference, bool zero_fixed = true);
  // Line-search merit: the free residual norm and the contact violation, in newtons.
  double merit(double residual_norm, const Eigen::VectorXd& x) const;
  // The strategy of SolverOptions::strategy, and the one its iterations with contacts take,
  // made once each (a change of strategy between frames allocates nothing). Throws bad_alloc.
  void choose_strategy(SolverOptions::Strategy strategy);
  // The strategy of the next iteration.
  UpdateStrategy& iteration_strategy() const;
  // step() without the exception barrier, and its parts.
  StepResult advance();
  // Out of time before a stage after the first: the step ends at the last stage.
  bool stage_out_of_time(StepResult& result) const;
  // Dynamic: x_ to the predicted state (solver.predictor); whether the rotations follow it, and
  // whether the contacts were detected there.
  bool predict(bool& contacts_detected);
  // Dynamic: the energy check of a step that iterated (a runaway diverges).
  void check_energy(StepResult& result);
  // Newton iterations from the current state; adds to result (iterations, timings, status).
  // contacts_detected: the contacts are already those of the current state. Past the time
  // budget it stops.
  void newton(StepResult& result, bool contacts_detected);
  struct Solve;  // what the iterations of one newton() call share
  struct LineSearch {
    double norm, merit, reference;  // at the point taken
    bool accepted;                  // a trial passed the merit or the potential test
    double alpha;                   // the share of the update taken
  };
  // Whether the solve ends before another iteration: non-finite, blown up, converged, capped.
  bool solve_ends(Solve& s);
  bool iteration_out_of_time(Solve& s, bool fresh_factor);
  // Newton iterations a solve may take: the solver's, or a recovery step's.
  int iteration_cap() const;
  // Past the cap, a frame with a time budget whose residual is above capped_residual iterates on.
  bool drifting(const Solve& s) const;
  // The deadline of a solve's iteration (1, 2, ...): past the cap, a frame far from equilibrium
  // is held to drift_deadline_, its factorisations included.
  std::chrono::steady_clock::time_point deadline_of(int iteration) const;
  // The matrix and factor the strategy asks for, and its update into dx_; false when it failed.
  bool newton_update(UpdateStrategy& update, Solve& s, bool fresh_factor);
  bool factorize(StepResult& result);
  // Backtracking from x_ along dx_ into x_try_, r_try_.
  LineSearch line_search(const Solve& s, bool contact_update);
  // An iteration without descent (or a contact update cut short) on an old factor: undone, to be
  // redone on a fresh factor when its factorisation fits in the time left; else kept when it
  // descended (the next iteration or step factorises first), or the step ends where the
  // iteration started.
  enum class Redo { Redone, Undone, Kept };
  Redo redo_on_fresh_factor(Solve& s, bool contact_update, bool descended);
  // Dynamic steps: the mechanical energy (kinetic + elastic) and the work of the loads and of
  // the constraints over the step that ended at x_ (J).
  double mechanical_energy(const Eigen::VectorXd& x, const Eigen::VectorXd& v);
  double work_over_step();
  // True once when the injected fault is f (it is then consumed).
  bool take_fault(InjectedFault f);
  // Those met after an accepted update.
  void take_faults_after_update();

  struct Snapshot {
    Eigen::VectorXd x, v, v_previous, x_start;
    double time = 0, state_energy = 0;
    bool rotations_continued = false;
    TangentFactor::State factor;
    MechanicalModel::EvaluationState mechanics;
    InstrumentContact::State contact;
  };
  void save(Snapshot& s);
  void restore(const Snapshot& s);
  Snapshot snapshot_;
  bool snapshot_valid_ = false;
  int rollbacks_in_a_row_ = 0;  // steps that diverged since the last one kept or recovery step
  InjectedFault fault_ = InjectedFault::None;
  long held_up_on_purpose_ = 0;
  std::chrono::steady_clock::time_point deadline_;  // of the step in progress (time_budget)
  std::chrono::steady_clock::time_point drift_deadline_;  // frames far from equilibrium iterate on until it
  bool recovering_ = false;  // the step in progress is a recovery (kRecoveryAfterRollbacks)

  MechanicalModel& mechanics_;
  InstrumentContact& contact_;
  SolverOptions solver_;
  NewtonMatrix matrix_;
  TangentFactor factor_;
  std::map<SolverOptions::Strategy, std::unique_ptr<UpdateStrategy>> strategies_;  // those chosen so far
  UpdateStrategy* strategy_ = nullptr;           // of solver_.strategy
  UpdateStrategy* contact_strategy_ = nullptr;   // its iterations with contacts

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
