#include "liver_sim/stepper/newton_stepper.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <new>
#include <sstream>
#include <stdexcept>
#include <thread>

namespace liver_sim {
namespace {

using Clock = std::chrono::steady_clock;
constexpr int kMaxKrylov = 30;      // GMRES iterations per Newton step
constexpr int kRefactorAfter = 10;  // GMRES iterations beyond which the factor is refreshed
// Modified Newton refreshes a factor whose iteration leaves more than this share of the residual
// it was asked to zero; with a change of the contact forces the stricter share (bench, probe
// sweeps on the cube and the phantom: 0.3-0.9 tried, doc/performance.md).
constexpr double kContraction = 0.9, kContactContraction = 0.5;
constexpr int kStallIterations = 5; // a capped step this long that ends no lower than it began has stalled
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

std::string stalled(double merit, double start_merit, int iterations) {
  std::ostringstream m;
  m << "stalled: residual " << merit << " N after " << iterations << " iterations, no lower than the " << start_merit
    << " N it started from";
  return m.str();
}

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
    : mechanics_(mechanics), contact_(contact), solver_(validated(solver)) {
  const SparsePattern& pattern = mechanics_.pattern();
  system_.assign(pattern.nonzeros(), 0.0);
  cholmod_.analyze(pattern.rows(), pattern.column_start(), pattern.row_index());
  if (solver_.background_refresh) make_background();
  x_ = x_start_ = mechanics_.rest_positions();
  v_ = Eigen::VectorXd::Zero(x_.size());
  v_previous_ = v_;
  for (Eigen::VectorXd* v : {&r_, &r_try_, &dx_, &x_try_, &f_tmp_, &v_tmp_, &f_ext_, &energy_work_}) v->setZero(x_.size());
}

std::string NewtonStepper::set_options(const SolverOptions& solver) {
  const std::string error = validate(solver);
  if (!error.empty()) return error;
  if (solver.mode != solver_.mode) return "solver.mode cannot change on a running model";
  if (solver.threads != solver_.threads) return "solver.threads cannot change on a running model";
  if (solver.background_refresh) {
    try {
      make_background();
    } catch (const std::exception& e) {  // no memory, no thread
      return std::string("solver.background_refresh: ") + e.what();
    }
  }
  // The factored matrix depends on dt and the damping (dynamic mode); the strategy and the
  // iteration controls leave it valid.
  if (solver.dt != solver_.dt || solver.rayleigh_mass != solver_.rayleigh_mass ||
      solver.rayleigh_stiffness != solver_.rayleigh_stiffness)
    drop_factor();
  // The predictor's acceleration and the rotations' angular velocity are differences over one
  // step: a new dt starts them afresh.
  if (solver.dt != solver_.dt) {
    v_previous_ = v_;
    rotations_continued_ = false;
  }
  // Turned off: a refresh asked for and not yet taken up happens in the step, as without it.
  if (solver_.background_refresh && !solver.background_refresh) {
    if (refresh_wanted_ || (background_ && !background_->idle())) factor_valid_ = false;
    refresh_wanted_ = false;
    if (background_) background_->cancel();
  }
  solver_ = solver;
  return "";
}

void NewtonStepper::set_positions(const Eigen::VectorXd& x) {
  x_ = x;
  state_energy_ = std::numeric_limits<double>::quiet_NaN();
  snapshot_valid_ = false;
}

void NewtonStepper::model_changed(bool refactorize) {
  state_energy_ = std::numeric_limits<double>::quiet_NaN();
  if (refactorize) drop_factor();
  snapshot_valid_ = false;  // its evaluation is of the model before the change
}

void NewtonStepper::reset() {
  snapshot_valid_ = false;
  drop_factor();
  state_energy_ = std::numeric_limits<double>::quiet_NaN();
  x_ = mechanics_.rest_positions();
  v_.setZero();
  v_previous_.setZero();
  rotations_continued_ = false;
  x_start_ = x_;
  time_ = 0;
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

void NewtonStepper::assemble_system() {
  // Static: A = K. Dynamic: A = (1 + b/dt) K + (1/dt^2 + a/dt) M.
  double k_scale = 1.0, m_scale = 0.0;
  if (solver_.mode == SolverOptions::Mode::Dynamic) {
    const double dt = solver_.dt;
    k_scale = 1.0 + solver_.rayleigh_stiffness / dt;
    m_scale = 1.0 / (dt * dt) + solver_.rayleigh_mass / dt;
  }
  mechanics_.assemble(k_scale, m_scale, system_);
}

void NewtonStepper::save(Snapshot& s) {
  s.x = x_;
  s.v = v_;
  s.v_previous = v_previous_;
  s.x_start = x_start_;
  s.time = time_;
  s.state_energy = state_energy_;
  s.rotations_continued = rotations_continued_;
  s.factor_valid = factor_valid_;
  s.refresh_wanted = refresh_wanted_;
  s.background_starts = background_starts_;
  s.factorizations = factorizations_;
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
  // The factor is the one from before the step unless the step replaced it.
  factor_valid_ = s.factor_valid && factorizations_ == s.factorizations;
  // A background factorisation started in the step is of a state given up; one started before
  // it is of the state restored.
  refresh_wanted_ = s.refresh_wanted;
  if (background_ && background_starts_ != s.background_starts) background_->cancel();
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
  deadline_ = t_step + std::chrono::duration_cast<Clock::duration>(
                           std::chrono::duration<double>(std::min(solver_.time_budget, 1e6)));
  StepResult result;
  x_start_ = x_;
  if (fault_ == InjectedFault::NotPositiveDefinite) drop_factor();  // a factorisation for the fault to meet
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
    // Out of time between stages, or a stage that would start with a factorisation the time left
    // cannot hold (the last stage ended short of convergence, so this one iterates, and its first
    // iteration factorises: a factor judged stale, or full Newton): the step ends at the last
    // stage, where the state and the instruments are consistent, and the next step starts with
    // the factorisation. A factorisation here overran the real-time frame by its whole length. A
    // stage that converged leaves the next to run: in free space it needs no iteration.
    if (k > 1 && (Clock::now() > deadline_ || (result.status != StepResult::Status::Converged &&
                                                factorizes(iteration_strategy()) && !factorization_fits()))) {
      result.status = StepResult::Status::NotConverged;
      result.message = "time budget";
      result.out_of_time = true;
      break;
    }
    contact_.begin_stage(k, stages, x_);
    // Dynamic: Newton starts from the predicted state (solver.predictor), whose error is
    // O(dt^2) or O(dt^3), not O(dt): one iteration of modified Newton then lands 100x closer to
    // the converged step (doc/performance.md). Not when the prediction carries a surface point
    // deep into an instrument (its contact would push it out on the wrong side).
    bool detected = false;
    if (dynamic && k == 1 && solver_.predictor != SolverOptions::Predictor::None) {
      x_ += solver_.dt * v_;
      if (solver_.predictor == SolverOptions::Predictor::ConstantAcceleration) x_ += solver_.dt * (v_ - v_previous_);
      bool predicted = true;
      if (contact_.num_instruments() > 0) {
        contact_.detect(x_);
        detected = true;
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
        rotations_predicted = true;
      }
    }
    newton(result, detected);
  }
  if (dynamic && result.status != StepResult::Status::Diverged && result.iterations > 0) {
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
      m << "energy growth: " << energy_after << " J after the step, " << energy_before << " J before, work "
        << work << " J";
      result.status = StepResult::Status::Diverged;
      result.message = m.str();
    }
  } else {
    state_energy_ = std::numeric_limits<double>::quiet_NaN();
  }
  if (result.status == StepResult::Status::Diverged) {
    restore(snapshot_);
  } else {
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

void NewtonStepper::drop_factor() {
  factor_valid_ = false;
  refresh_wanted_ = false;
  if (background_) background_->cancel();
}

void NewtonStepper::make_background() {
  if (background_) return;
  const SparsePattern& pattern = mechanics_.pattern();
  background_ = std::make_unique<BackgroundFactorization>(pattern.rows(), pattern.column_start(), pattern.row_index());
}

void NewtonStepper::refresh_in_background(StepResult& result) {
  if (const std::optional<bool> taken = background_->take(cholmod_)) {
    refresh_wanted_ = false;  // a new factor has not been judged yet
    if (*taken) {
      ++factorizations_;  // a rollback sees the new factor
      ++result.background_factorizations;
    } else {
      factor_valid_ = false;  // not positive definite: the factorisation in the step meets it and rolls back
    }
  }
  if (factor_valid_ && refresh_wanted_ && background_->idle()) {
    const auto t0 = Clock::now();
    assemble_system();  // where the residual was last evaluated: the iterate
    result.timing.assembly_ms += ms_since(t0);
    background_->start(system_);
    ++background_starts_;
    refresh_wanted_ = false;
  }
}

bool NewtonStepper::factorization_fits() const { return Clock::now() + factorization_time_ <= deadline_; }

SolverOptions::Strategy NewtonStepper::iteration_strategy() const {
  // With contacts, the strategies that solve with the factor carry the contact forces in the
  // same solve; the others become Newton-Krylov, which has the factor too.
  using Strategy = SolverOptions::Strategy;
  const bool direct = solver_.strategy == Strategy::ModifiedNewton || solver_.strategy == Strategy::FullNewton;
  return contact_.active() && !direct ? Strategy::NewtonKrylov : solver_.strategy;
}

bool NewtonStepper::factorizes(SolverOptions::Strategy strategy) const {
  using Strategy = SolverOptions::Strategy;
  const bool uses_factor = strategy != Strategy::FullNewtonEigen && strategy != Strategy::CG;
  return uses_factor && (!factor_valid_ || strategy == Strategy::FullNewton);  // full Newton in every iteration
}

double NewtonStepper::merit(double residual_norm, const Eigen::VectorXd& x) const {
  // A contact violation counts as the force that a stiffness E L would need to close it.
  const double k = mechanics_.parenchyma().young_modulus * mechanics_.length_scale() * contact_.violation(x);
  return std::sqrt(residual_norm * residual_norm + k * k);
}

void NewtonStepper::newton(StepResult& result, bool contacts_detected) {
  auto fail = [&](const std::string& why) {
    result.status = StepResult::Status::Diverged;
    result.message = why;
  };
  const std::vector<char>& fixed = mechanics_.fixed_dofs();
  const SparsePattern& pattern = mechanics_.pattern();
  const double force_floor = mechanics_.force_floor();
  const int iterations_before = result.iterations;
  bool refreshed = false;  // a modified-Newton iteration on an old factor was redone on a new one
  auto t0 = Clock::now();
  double reference = 0;
  if (!contacts_detected) contact_.detect(x_);
  double norm = residual(x_, r_, &reference);
  const double start_merit = merit(norm, x_);
  result.timing.assembly_ms += ms_since(t0);
  result.status = StepResult::Status::NotConverged;
  while (true) {
    if (!std::isfinite(norm)) {
      fail("non-finite residual");
      break;
    }
    const double current_merit = merit(norm, x_);
    // The line search keeps the merit near its start; a millionfold growth means the iteration
    // has left the basin (possible without line search).
    if (current_merit > 1e6 * std::max(start_merit, force_floor)) {
      std::ostringstream m;
      m << "residual blow-up: " << current_merit << " N against " << start_merit << " N at the start of the step";
      fail(m.str());
      break;
    }
    result.residual = norm / reference;
    // Relative to the forces at play; the absolute floor is round-off, for states near rest.
    // With instruments, the contact conditions must hold too.
    if (norm <= std::max(solver_.tolerance * reference, force_floor) &&
        (!contact_.active() || contact_.violation(x_) <= contact_.options().tolerance)) {
      result.status = StepResult::Status::Converged;
      break;
    }
    if (result.iterations - iterations_before == solver_.max_iterations) {
      // Capped but closer to equilibrium: kept, the next step continues (real-time frames).
      // No closer after all the iterations: stalled, rolled back like a divergence. A step
      // capped below kStallIterations is a real-time frame absorbing a new input, whose merit
      // may rise while the next frames continue from it; a runaway is still caught by the
      // blow-up, energy and finiteness checks.
      if (current_merit >= start_merit && solver_.max_iterations >= kStallIterations) {
        fail(stalled(current_merit, start_merit, solver_.max_iterations));
      } else {
        result.message = "iteration cap";  // within the string's inline buffer: no allocation per frame
      }
      break;
    }
    using Strategy = SolverOptions::Strategy;
    const Strategy strategy = iteration_strategy();
    const bool direct = strategy == Strategy::ModifiedNewton || strategy == Strategy::FullNewton;  // contacts in the solve
    const bool current_tangent = strategy == Strategy::FullNewton || strategy == Strategy::FullNewtonEigen ||
                                 strategy == Strategy::ReusedFactorCG || strategy == Strategy::CG;
    if (strategy == Strategy::ModifiedNewton && solver_.background_refresh && factor_valid_) refresh_in_background(result);
    const bool fresh_factor = factorizes(strategy);
    // Out of time: the iterate is kept, judged as at the cap (a stall needs kStallIterations
    // iterations to judge). The first iteration of a step always runs, so that every frame moves
    // on. After an iteration of the same stage (a stage's start has moved its instruments), a
    // factorisation that the time left cannot hold starts the next step instead: an iteration
    // and a factorisation in one real-time frame overrun it by the factorisation, and the inputs
    // that arrive meanwhile (clouds, poses) wait or are replaced.
    if (result.iterations > 0 &&
        (Clock::now() > deadline_ || (result.iterations > iterations_before && fresh_factor && !factorization_fits()))) {
      const int done = result.iterations - iterations_before;
      if (current_merit >= start_merit && done >= kStallIterations && solver_.max_iterations >= kStallIterations) {
        fail(stalled(current_merit, start_merit, done));
      } else {
        result.out_of_time = true;
        result.message = "time budget";
      }
      break;
    }
    ++result.iterations;
    if (strategy == Strategy::FullNewton) factor_valid_ = false;
    if (!factor_valid_ || current_tangent) {
      t0 = Clock::now();
      assemble_system();
      result.timing.assembly_ms += ms_since(t0);
    }
    if (strategy == Strategy::FullNewtonEigen) {
      t0 = Clock::now();
      const Eigen::Map<const Eigen::SparseMatrix<double>> A(pattern.rows(), pattern.rows(), pattern.nonzeros(),
                                                            pattern.column_start().data(), pattern.row_index().data(),
                                                            system_.data());
      if (!eigen_analyzed_) eigen_ldlt_.analyzePattern(A);
      eigen_analyzed_ = true;
      eigen_ldlt_.factorize(A);
      result.timing.factorization_ms += ms_since(t0);
      ++result.factorizations;
      if (eigen_ldlt_.info() != Eigen::Success || (eigen_ldlt_.vectorD().array() <= 0).any()) {
        fail("tangent matrix is not positive definite");
        break;
      }
    }
    // The factor of an earlier tangent keeps serving as the preconditioner (GMRES works on the
    // true Jacobian) until it no longer preconditions well or the constraints changed.
    if (fresh_factor) {
      t0 = Clock::now();
      if (take_fault(InjectedFault::NotPositiveDefinite))
        for (int i = 0; i < pattern.rows(); ++i)
          if (!fixed[i]) {
            system_[pattern.diagonal(i)] = -1;
            break;
          }
      // A background one would replace this newer factor, which has not been judged yet.
      if (background_) background_->cancel();
      refresh_wanted_ = false;
      const bool factored = cholmod_.factorize(system_);
      factorization_time_ = Clock::now() - t0;
      ++factorizations_;
      result.timing.factorization_ms += ms_since(t0);
      ++result.factorizations;
      if (!factored) {
        fail("tangent matrix is not positive definite");
        break;
      }
      factor_valid_ = true;
    }
    // Newton-Krylov: GMRES on the true Jacobian (directional differences of the residual),
    // preconditioned by the factorised corotational tangent. The tangent alone misses the
    // rotation derivative and the follower-load stiffness, which under suction on soft tissue
    // are as large as the material stiffness and make a plain modified Newton crawl.
    t0 = Clock::now();
    // A factorisation costs far more than a GMRES iteration: solve each linearisation well.
    const double forcing = std::clamp(0.1 * solver_.tolerance * reference / current_merit, 1e-6, 0.1);
    // The contact problem's share of the force residual the step must reach.
    const double force_tolerance = 0.1 * std::max(solver_.tolerance * reference, force_floor);
    // The operators capture `this` only: a std::function keeps that without an allocation.
    const Gmres::Operator jacobian = [this](const Eigen::VectorXd& v, Eigen::VectorXd& out) {
      const double h = 1e-8 * mechanics_.length_scale() / std::max(v.cwiseAbs().maxCoeff(), 1e-300);
      x_try_ = x_ + h * v;
      double unused;
      residual(x_try_, out, &unused);
      const std::vector<char>& fixed = mechanics_.fixed_dofs();
      for (int i = 0; i < out.size(); ++i) out[i] = fixed[i] ? v[i] : (r_[i] - out[i]) / h;
    };
    const Gmres::Operator preconditioner = [this](const Eigen::VectorXd& in, Eigen::VectorXd& out) {
      cholmod_.solve(in, out);
    };
    const Gmres::Operator tangent = [this](const Eigen::VectorXd& v, Eigen::VectorXd& out) {
      mechanics_.pattern().multiply(system_, v, out);
    };
    int krylov = 0;
    if (direct && contact_.active()) {
      const auto t_contact = Clock::now();
      result.contact_sweeps += contact_.direct_update(cholmod_, r_, force_tolerance, dx_).sweeps;
      result.timing.contact_ms += ms_since(t_contact);
    } else if (strategy == Strategy::FullNewton || strategy == Strategy::ModifiedNewton) {
      cholmod_.solve(r_, dx_);
    } else if (strategy == Strategy::FullNewtonEigen) {
      dx_ = eigen_ldlt_.solve(r_);
    } else if (strategy == Strategy::ReusedFactorCG) {
      krylov = cg_.solve(tangent, preconditioner, r_, dx_, forcing, kMaxKrylov);
      if (krylov > kRefactorAfter || cg_.relative_residual() > forcing) factor_valid_ = false;
    } else if (strategy == Strategy::CG) {
      jacobi_.resize(pattern.rows());
      for (int i = 0; i < pattern.rows(); ++i) jacobi_[i] = 1.0 / system_[pattern.diagonal(i)];
      const Gmres::Operator jacobi = [this](const Eigen::VectorXd& in, Eigen::VectorXd& out) { out = jacobi_.cwiseProduct(in); };
      krylov = cg_.solve(tangent, jacobi, r_, dx_, forcing, 20 * kMaxKrylov * kMaxKrylov);
    } else if (!contact_.active()) {
      krylov = gmres_.solve(jacobian, preconditioner, r_, dx_, forcing, kMaxKrylov);
      if (krylov > kRefactorAfter || gmres_.relative_residual() > forcing) factor_valid_ = false;
    } else {
      const auto t_contact = Clock::now();
      const InstrumentContact::Update update = contact_.krylov_update(cholmod_, jacobian, r_, forcing, force_tolerance, dx_);
      result.contact_sweeps += update.sweeps;
      krylov = update.krylov;
      result.timing.contact_ms += ms_since(t_contact);
      if (krylov > kRefactorAfter || update.relative_residual > forcing) factor_valid_ = false;
    }
    result.linear_iterations += krylov;
    result.timing.solve_ms += ms_since(t0);
    if (take_fault(InjectedFault::NonFinite)) dx_[0] = std::numeric_limits<double>::quiet_NaN();
    if (!dx_.allFinite()) {
      fail("non-finite Newton update");
      break;
    }

    // Backtracking guards far from the solution. A step is accepted when the merit (free
    // residual and constraint gap) falls enough, or when the potential falls along it: the slope
    // r . dx at the trial point, against the slope at the start, says so (trapezoid rule). The
    // second test keeps full steps that raise the residual only because the linear step
    // over-stretches rotating elements, as in the first step of a bending problem.
    t0 = Clock::now();
    double slope0 = 0;
    for (int i = 0; i < r_.size(); ++i)
      if (!fixed[i]) slope0 += r_[i] * dx_[i];
    // best_norm starts as NaN: a search whose every trial is non-finite ends at the detector.
    double alpha = 1.0, best_alpha = 1.0, best_norm = std::numeric_limits<double>::quiet_NaN(),
           best_merit = std::numeric_limits<double>::infinity();
    double ref_try = reference;
    const int max_halvings = solver_.line_search ? 6 : 0;
    bool accepted = false;  // a trial passed the merit or the potential test
    // With the direct contact update the trial point carries the same share of the contact
    // force change: a capped real-time frame then ends where its force balance is (without it,
    // 38 of 300 haptic frames rolled back as stalled). The Krylov update keeps its forces:
    // scaled, its steps took twice the iterations (bench, probe on the cube).
    const bool contact_update = contact_.active() && direct;
    for (int h = 0;; ++h) {
      x_try_ = x_ + alpha * dx_;
      if (contact_update) contact_.scale_update(alpha);
      const double n_try = residual(x_try_, r_try_, &ref_try);
      const double m_try = merit(n_try, x_try_);
      const bool merit_falls = m_try <= (1.0 - 1e-4 * alpha) * current_merit;
      const bool potential_falls = std::isfinite(m_try) && slope0 > 0 && r_try_.dot(dx_) >= -0.5 * slope0;
      if (merit_falls || potential_falls || m_try < best_merit) {
        best_merit = m_try;
        best_norm = n_try;
        best_alpha = alpha;
      }
      accepted = merit_falls || potential_falls;
      if (accepted || h == max_halvings) break;
      alpha *= 0.5;
    }
    // None was good enough: take the best one tried.
    if (best_alpha != alpha) {
      x_try_ = x_ + best_alpha * dx_;
      if (contact_update) contact_.scale_update(best_alpha);
      best_norm = residual(x_try_, r_try_, &ref_try);
    }
    result.timing.assembly_ms += ms_since(t0);
    // Modified Newton on an old factor that finds no descent (no trial accepted, or only by the
    // potential test in the last iteration allowed, which would end the step above where it
    // started and roll it back as stalled): the factor no longer fits the state. Refactorise
    // at x (evaluated again: the tangent is assembled where the last evaluation was) and redo
    // the iteration, once per Newton solve (per instrument stage), instead of spending it. When
    // the factorisation would overrun the time budget, the frame ends where the iteration
    // started, and the next one starts with the factorisation.
    const bool last_iteration = result.iterations - iterations_before == solver_.max_iterations;
    if (strategy == Strategy::ModifiedNewton && !fresh_factor && !refreshed && best_merit >= current_merit &&
        (!accepted || last_iteration)) {
      factor_valid_ = false;
      if (contact_update) contact_.scale_update(0.0);
      if (!factorization_fits()) {
        result.out_of_time = true;
        result.message = "time budget";
        norm = residual(x_, r_, &reference);  // the evaluation is the trial's
        break;
      }
      refreshed = true;
      --result.iterations;
      norm = residual(x_, r_, &reference);
      continue;
    }
    x_.swap(x_try_);
    r_.swap(r_try_);
    if (take_fault(InjectedFault::Exception)) throw std::runtime_error("injected fault (test hook)");
    if (take_fault(InjectedFault::OutOfMemory)) throw std::bad_alloc();
    if (take_fault(InjectedFault::Slow)) {
      std::this_thread::sleep_for(kInjectedDelay);
      ++held_up_on_purpose_;
    }
    // Modified Newton keeps its factor while it contracts the residual well: the residual it
    // was asked to zero, which carries the update's change of the contact forces (a step that
    // closes new gaps raises the residual it started from). When contact forces changed, the
    // factor also set them (through the Delassus operator), so an old one errs in the forces
    // more than its residual shows: it must contract further. A factor is judged by the
    // iterations after the one that made it: that one's contraction measures how far the problem
    // is from linear here (contacts coming and going), which a factor made one iteration later
    // meets as well. In the soak's frames a fresh factor left more than half of the residual
    // about as often as an older one (33% and 29% of the iterations with contact forces changing).
    if (strategy == Strategy::ModifiedNewton) {
      double asked = norm, contraction = kContraction;
      if (contact_update) {
        f_tmp_ = r_try_;  // the residual where the iteration started (swapped above)
        if (contact_.add_force_change(f_tmp_)) contraction = kContactContraction;
        for (int i = 0; i < f_tmp_.size(); ++i)
          if (fixed[i]) f_tmp_[i] = 0;
        asked = f_tmp_.norm();
      }
      if (best_norm > contraction * asked && !fresh_factor) {
        if (solver_.background_refresh)
          refresh_wanted_ = true;  // the old factor serves meanwhile
        else
          factor_valid_ = false;
      }
    }
    norm = best_norm;
    reference = ref_try;
    if (contact_.detect(x_)) norm = residual(x_, r_, &reference);
  }
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
