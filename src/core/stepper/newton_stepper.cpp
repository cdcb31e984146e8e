#include "liver_sim/stepper/newton_stepper.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <new>
#include <sstream>
#include <stdexcept>
#include <thread>

#include "update_strategy.h"

namespace liver_sim {
namespace {

using Clock = std::chrono::steady_clock;

const SolverOptions& validated(const SolverOptions& o) {
  const std::string error = validate(o);
  if (!error.empty()) throw std::invalid_argument(error);
  return o;
}

double free_norm(const Eigen::VectorXd& r, const std::vector<char>& fixed) {
  double s = 0;
  for (int i = 0; i < r.size(); ++i)
    if (!fixed[i]) s += r[i] * r[i];
  return std::sqrt(s);
}

}  // namespace

NewtonStepper::NewtonStepper(MechanicalModel& mechanics, InstrumentContact& contact, const SolverOptions& solver)
    : mechanics_(mechanics),
      contact_(contact),
      solver_(validated(solver)),
      matrix_(mechanics, solver_),
      factor_(mechanics.pattern()) {
  choose_strategy(solver_.strategy);
  if (solver_.background_refresh) factor_.start_background();
  x_ = x_start_ = mechanics_.rest_positions();
  v_ = Eigen::VectorXd::Zero(x_.size());
  v_previous_ = v_;
  for (Eigen::VectorXd* v : {&r_, &r_try_, &dx_, &x_try_, &f_tmp_, &v_tmp_, &f_ext_, &energy_work_}) v->setZero(x_.size());
}

NewtonStepper::~NewtonStepper() = default;

void NewtonStepper::choose_strategy(SolverOptions::Strategy strategy) {
  const auto made = [this](SolverOptions::Strategy s) -> UpdateStrategy& {
    std::unique_ptr<UpdateStrategy>& p = strategies_[s];
    if (!p) p = make_update_strategy(s, StrategyParts{mechanics_, contact_, matrix_, factor_, solver_});
    return *p;
  };
  UpdateStrategy& chosen = made(strategy);
  contact_strategy_ = &made(chosen.with_contacts());
  strategy_ = &chosen;
}

UpdateStrategy& NewtonStepper::iteration_strategy() const {
  return contact_.active() ? *contact_strategy_ : *strategy_;
}

std::string NewtonStepper::set_options(const SolverOptions& solver) {
  const std::string error = validate(solver);
  if (!error.empty()) return error;
  if (solver.mode != solver_.mode) return "solver.mode cannot change on a running model";
  if (solver.threads != solver_.threads) return "solver.threads cannot change on a running model";
  if (solver.background_refresh) {
    try {
      factor_.start_background();
    } catch (const std::exception& e) {  // no memory, no thread
      return std::string("solver.background_refresh: ") + e.what();
    }
  }
  try {
    choose_strategy(solver.strategy);
  } catch (const std::exception& e) {  // no memory
    return std::string("solver.strategy: ") + e.what();
  }
  // The factored matrix depends on dt and the damping (dynamic mode); the strategy and the
  // iteration controls leave it valid.
  if (solver.dt != solver_.dt || solver.rayleigh_mass != solver_.rayleigh_mass ||
      solver.rayleigh_stiffness != solver_.rayleigh_stiffness)
    factor_.drop();
  // The predictor's acceleration and the rotations' angular velocity are differences over one
  // step: a new dt starts them afresh.
  if (solver.dt != solver_.dt) {
    v_previous_ = v_;
    rotations_continued_ = false;
  }
  if (solver_.background_refresh && !solver.background_refresh) factor_.stop_background();
  solver_ = solver;
  return "";
}

void NewtonStepper::set_positions(const Eigen::VectorXd& x) {
  x_ = x;
  state_energy_ = std::numeric_limits<double>::quiet_NaN();
  snapshot_valid_ = false;
  rollbacks_in_a_row_ = 0;
}

void NewtonStepper::model_changed(bool refactorize) {
  state_energy_ = std::numeric_limits<double>::quiet_NaN();
  if (refactorize) factor_.drop();
  snapshot_valid_ = false;  // its evaluation is of the model before the change
}

void NewtonStepper::reset() {
  snapshot_valid_ = false;
  factor_.drop();
  state_energy_ = std::numeric_limits<double>::quiet_NaN();
  x_ = mechanics_.rest_positions();
  v_.setZero();
  v_previous_.setZero();
  rotations_continued_ = false;
  x_start_ = x_;
  time_ = 0;
  rollbacks_in_a_row_ = 0;
}

double NewtonStepper::mechanical_energy(const Eigen::VectorXd& x, const Eigen::VectorXd& v) {
  return 0.5 * v.dot(mechanics_.mass().cwiseProduct(v)) + mechanics_.elastic_energy(x);
}

double NewtonStepper::work_over_step() {
  // Loads: trapezoid rule between the start and the end of the step. Instruments: their force
  // at the end of the step times the displacement (they move only the nodes they touch).
  mechanics_.external_forces(x_start_, f_ext_);
  mechanics_.external_forces(x_, energy_work_);
  f_ext_ = 0.5 * load_scale_ * (f_ext_ + energy_work_);
  contact_.add_forces(x_, f_ext_);
  if (!mechanics_.surface_targets().empty() || mechanics_.surface_loads().size() != 0) {
    energy_work_.setZero();
    mechanics_.add_target_forces(x_start_, energy_work_);
    mechanics_.add_target_forces(x_, energy_work_);
    f_ext_ += 0.5 * energy_work_;
  }
  const std::vector<char>& fixed = mechanics_.fixed_dofs();
  double work = 0;
  for (int i = 0; i < x_.size(); ++i)
    if (!fixed[i]) work += (x_[i] - x_start_[i]) * f_ext_[i];
  return work;
}

double NewtonStepper::residual(const Eigen::VectorXd& x, Eigen::VectorXd& r, double* reference, bool zero_fixed) {
  const std::vector<char>& fixed = mechanics_.fixed_dofs();
  mechanics_.internal_forces(x, f_tmp_);
  mechanics_.external_forces(x, r);
  r *= load_scale_;
  mechanics_.add_target_forces(x, r);
  const double load_norm = free_norm(r, fixed);
  // All DOFs: under prescribed displacements alone the reactions are the force scale.
  const double internal_norm = f_tmp_.norm();
  r -= f_tmp_;
  contact_.add_forces(x, r);
  if (solver_.mode == SolverOptions::Mode::Dynamic) {
    const double dt = solver_.dt;
    // Backward Euler: M (v - v_n)/dt + D v = f_ext - f_int, v = (x - x_n)/dt, D = a M + b K.
    v_tmp_ = (x - x_start_) / dt;
    r -= mechanics_.mass().cwiseProduct((v_tmp_ - v_) / dt + solver_.rayleigh_mass * v_tmp_);
    if (solver_.rayleigh_stiffness > 0 && !v_tmp_.isZero(0.0)) {  // v = 0: at rest, or before any step
      mechanics_.damping_forces(v_tmp_, f_tmp_);
      r -= solver_.rayleigh_stiffness * f_tmp_;
    }
  }
  for (int i = 0; zero_fixed && i < r.size(); ++i)
    if (fixed[i]) r[i] = 0;
  *reference = std::max({load_norm, internal_norm, mechanics_.force_floor()});
  return r.norm();
}


void NewtonStepper::save(Snapshot& s) {
  s.x = x_;
  s.v = v_;
  s.v_previous = v_previous_;
  s.x_start = x_start_;
  s.time = time_;
  s.state_energy = state_energy_;
  s.rotations_continued = rotations_continued_;
  factor_.save(s.factor);
  mechanics_.save(s.mechanics);
  contact_.save(s.contact);
}

void NewtonStepper::restore(const Snapshot& s) {
  x_ = s.x;
  v_ = s.v;
  v_previous_ = s.v_previous;
  x_start_ = s.x_start;
  time_ = s.time;
  state_energy_ = s.state_energy;
  rotations_continued_ = s.rotations_continued;
  factor_.restore(s.factor);
  mechanics_.restore(s.mechanics);
  contact_.restore(s.contact);
}

bool NewtonStepper::undo_step() {
  if (!snapshot_valid_) return false;
  restore(snapshot_);
  snapshot_valid_ = false;
  return true;
}

bool NewtonStepper::take_fault(InjectedFault f) {
  if (fault_ != f) return false;
  fault_ = InjectedFault::None;
  return true;
}

void NewtonStepper::take_faults_after_update() {
  if (take_fault(InjectedFault::Exception)) throw std::runtime_error("injected fault (test hook)");
  if (take_fault(InjectedFault::OutOfMemory)) throw std::bad_alloc();
  if (take_fault(InjectedFault::Slow)) {
    std::this_thread::sleep_for(kInjectedDelay);
    ++held_up_on_purpose_;
  }
}

StepResult NewtonStepper::step() {
  snapshot_valid_ = false;
  save(snapshot_);
  snapshot_valid_ = true;
  try {
    return advance();
  } catch (...) {  // whatever it was, the model stays the one before the step
    restore(snapshot_);
    throw;
  }
}

StepResult NewtonStepper::advance() {
  const auto t_step = Clock::now();
  // Beyond 1e6 s the budget is no limit in practice, and the clock's range holds it.
  recovering_ = rollbacks_in_a_row_ >= kRecoveryAfterRollbacks;
  const double budget = recovering_ ? kRecoveryBudgets * solver_.time_budget : solver_.time_budget;
  const auto seconds = [](double s) {
    return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(std::min(s, 1e6)));
  };
  deadline_ = t_step + seconds(budget);
  drift_deadline_ = t_step + seconds(kDriftBudgetShare * budget);
  StepResult result;
  result.recovery = recovering_;
  x_start_ = x_;
  if (fault_ == InjectedFault::NotPositiveDefinite) factor_.drop();  // a factorisation for the fault to meet
  const bool dynamic = solver_.mode == SolverOptions::Mode::Dynamic;
  if (dynamic && solver_.rayleigh_stiffness > 0) {
    // Rayleigh damping b K v with the stiffness of the state the step starts from, fixed within
    // the step so that the residual stays one function of x while Newton iterates; applied
    // element by element, not assembled (an assembly per step cost a third of a haptic frame).
    const auto t0 = Clock::now();
    mechanics_.snapshot_damping(x_start_);
    result.timing.assembly_ms += ms_since(t0);
  }
  const int stages = contact_.begin_step(time_ + solver_.dt, x_);
  bool rotations_predicted = false;
  for (int k = 1; k <= stages && result.status != StepResult::Status::Diverged && !result.out_of_time; ++k) {
    if (k > 1 && stage_out_of_time(result)) break;
    contact_.begin_stage(k, stages, x_);
    bool detected = false;
    if (dynamic && k == 1 && solver_.predictor != SolverOptions::Predictor::None) rotations_predicted = predict(detected);
    newton(result, detected);
  }
  if (dynamic && result.status != StepResult::Status::Diverged && result.iterations > 0) {
    check_energy(result);
  } else {
    state_energy_ = std::numeric_limits<double>::quiet_NaN();
  }
  if (result.status == StepResult::Status::Diverged) {
    restore(snapshot_);
    // A recovery step that diverges too is followed by ordinary frames again: at most one
    // frame in three runs long while the model does not recover.
    rollbacks_in_a_row_ = recovering_ ? 0 : rollbacks_in_a_row_ + 1;
  } else {
    rollbacks_in_a_row_ = 0;
    rotations_continued_ = rotations_predicted;
    if (dynamic) {
      v_previous_.swap(v_);
      v_ = (x_ - x_start_) / solver_.dt;
    }
    time_ += solver_.dt;
    contact_.end_step(x_);
  }
  result.contacts = contact_.loaded_contacts();
  result.timing.total_ms = ms_since(t_step);
  return result;
}

bool NewtonStepper::stage_out_of_time(StepResult& result) const {
  // Out of time between stages, or a stage that would start with a factorisation the time left
  // cannot hold (the last stage ended short of convergence, so this one iterates, and its first
  // iteration factorises: a factor judged stale, or full Newton): the step ends at the last
  // stage, where the state and the instruments are consistent, and the next step starts with
  // the factorisation. A factorisation here overran the real-time frame by its whole length. A
  // stage that converged leaves the next to run: in free space it needs no iteration.
  if (!(Clock::now() > deadline_ || (result.status != StepResult::Status::Converged &&
                                     iteration_strategy().factorizes() && !factor_.fits(deadline_))))
    return false;
  result.status = StepResult::Status::NotConverged;
  result.message = "time budget";
  result.out_of_time = true;
  return true;
}

bool NewtonStepper::predict(bool& contacts_detected) {
  // Dynamic: Newton starts from the predicted state (solver.predictor), whose error is
  // O(dt^2) or O(dt^3), not O(dt): one iteration of modified Newton then lands 100x closer to
  // the converged step (doc/performance.md). Not when the prediction carries a surface point
  // deep into an instrument (its contact would push it out on the wrong side).
  x_ += solver_.dt * v_;
  if (solver_.predictor == SolverOptions::Predictor::ConstantAcceleration) x_ += solver_.dt * (v_ - v_previous_);
  bool predicted = true;
  if (contact_.num_instruments() > 0) {
    contact_.detect(x_);
    contacts_detected = true;
    if (contact_.deep(x_)) {
      x_ = x_start_;
      contact_.detect(x_);
      predicted = false;
    }
  }
  // The rotations follow the prediction as a guess (warm polar iterations), when they are
  // those of x_n.
  if (predicted && mechanics_.evaluated_at(x_start_)) {
    mechanics_.predict_rotations(rotations_continued_);
    return true;
  }
  return false;
}

void NewtonStepper::check_energy(StepResult& result) {
  // Backward Euler dissipates: the energy cannot exceed what it had plus the work done on it.
  // A margin of 2 leaves room for the follower loads and the corotational approximation;
  // what it catches is a runaway. The energy at the start is the last step's end when known.
  const double energy_before = std::isnan(state_energy_) ? mechanical_energy(x_start_, v_) : state_energy_;
  v_tmp_ = (x_ - x_start_) / solver_.dt;
  const double energy_after = mechanical_energy(x_, v_tmp_);
  const double work = work_over_step();
  state_energy_ = energy_after;
  if (!std::isfinite(energy_after) ||
      energy_after > 2 * (energy_before + std::abs(work)) + mechanics_.force_floor() * mechanics_.length_scale()) {
    std::ostringstream m;
    m << "energy growth: " << energy_after << " J after the step, " << energy_before << " J before, work " << work
      << " J";
    result.status = StepResult::Status::Diverged;
    result.message = m.str();
  }
}

double NewtonStepper::merit(double residual_norm, const Eigen::VectorXd& x) const {
  // A contact violation counts as the force that a stiffness E L would need to close it.
  const double k = mechanics_.parenchyma().young_modulus * mechanics_.length_scale() * contact_.violation(x);
  return std::sqrt(residual_norm * residual_norm + k * k);
}

Eigen::VectorXd NewtonStepper::support_forces() {
  double unused;
  residual(x_, r_try_, &unused, /*zero_fixed=*/false);
  const std::vector<char>& fixed = mechanics_.fixed_dofs();
  Eigen::VectorXd f = Eigen::VectorXd::Zero(x_.size());
  for (int i = 0; i < f.size(); ++i)
    if (fixed[i]) f[i] = -r_try_[i];  // the support balances the residual
  return f;
}

}  // namespace liver_sim
