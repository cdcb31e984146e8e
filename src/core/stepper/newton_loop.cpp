// The Newton loop of NewtonStepper (newton_stepper.h): from the stage's state, iterations of the
// update strategy's step (update_strategy.h), each judged (finite, no blow-up, converged, capped,
// in time), searched along and accepted, until the solve ends.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "liver_sim/stepper/newton_stepper.h"
#include "update_strategy.h"

namespace liver_sim {
namespace {

using Clock = std::chrono::steady_clock;
constexpr int kStallIterations = 5; // a capped step this long that ends no lower than it began has stalled

std::string stalled(double merit, double start_merit, int iterations) {
  std::ostringstream m;
  m << "stalled: residual " << merit << " N after " << iterations << " iterations, no lower than the " << start_merit
    << " N it started from";
  return m.str();
}

}  // namespace

// What the iterations of one Newton solve (one instrument stage) share.
struct NewtonStepper::Solve {
  StepResult& result;
  int iterations_before;    // result.iterations when the solve began
  double start_merit = 0;   // N, where it began
  double norm = 0, reference = 0, merit = 0;  // at x_: the free residual norm, its reference, the merit
  bool refreshed = false;   // an iteration without descent on an old factor was redone on a fresh one
  int done() const { return result.iterations - iterations_before; }
  void fail(const std::string& why) {
    result.status = StepResult::Status::Diverged;
    result.message = why;
  }
};

void NewtonStepper::newton(StepResult& result, bool contacts_detected) {
  Solve s{result, result.iterations};
  const auto t0 = Clock::now();
  if (!contacts_detected) contact_.detect(x_);
  s.norm = residual(x_, r_, &s.reference);
  s.start_merit = merit(s.norm, x_);
  result.timing.assembly_ms += ms_since(t0);
  result.status = StepResult::Status::NotConverged;
  while (!solve_ends(s)) {
    UpdateStrategy& update = iteration_strategy();
    update.begin_iteration(result);
    const bool fresh_factor = update.factorizes();
    if (iteration_out_of_time(s, fresh_factor)) break;
    ++result.iterations;
    if (!newton_update(update, s, fresh_factor)) break;
    const bool contact_update = contact_.active() && update.scales_contact_forces();
    const LineSearch taken = line_search(s, contact_update);
    // An iteration on an old factor that finds no descent (no trial accepted, or only by the
    // potential test in the last iteration allowed, which would end the step above where it
    // started and roll it back as stalled), or whose contact update the search had to cut
    // short: the factor no longer fits the state. Redone on a fresh one, once per Newton solve
    // (per instrument stage), instead of spent. A cut contact update leaves the gaps it was to
    // close open, frame after frame while the factor is kept (doc/performance.md).
    const bool no_descent = taken.merit >= s.merit && (!taken.accepted || s.done() == iteration_cap());
    if (update.redoes_without_descent() && !fresh_factor && !s.refreshed &&
        (no_descent || (contact_update && taken.alpha < 1))) {
      const Redo redo = redo_on_fresh_factor(s, contact_update, taken.merit < s.merit);
      if (redo == Redo::Redone) continue;
      if (redo == Redo::Undone) break;
    }
    x_.swap(x_try_);
    r_.swap(r_try_);
    if (s.done() > iteration_cap()) result.past_cap = true;
    take_faults_after_update();
    update.end_iteration({r_try_, s.norm, taken.norm, fresh_factor, contact_update});  // r_try_: where it started
    s.norm = taken.norm;
    s.reference = taken.reference;
    if (contact_.detect(x_)) s.norm = residual(x_, r_, &s.reference);
  }
}

bool NewtonStepper::solve_ends(Solve& s) {
  if (!std::isfinite(s.norm)) {
    s.fail("non-finite residual");
    return true;
  }
  s.merit = merit(s.norm, x_);
  // The line search keeps the merit near its start; a millionfold growth means the iteration
  // has left the basin (possible without line search).
  const double force_floor = mechanics_.force_floor();
  if (s.merit > 1e6 * std::max(s.start_merit, force_floor)) {
    std::ostringstream m;
    m << "residual blow-up: " << s.merit << " N against " << s.start_merit << " N at the start of the step";
    s.fail(m.str());
    return true;
  }
  s.result.residual = s.norm / s.reference;
  // Relative to the forces at play; the absolute floor is round-off, for states near rest.
  // With instruments, the contact conditions must hold too.
  if (s.norm <= std::max(solver_.tolerance * s.reference, force_floor) &&
      (!contact_.active() || contact_.violation(x_) <= contact_.options().tolerance)) {
    s.result.status = StepResult::Status::Converged;
    return true;
  }
  const int cap = iteration_cap();
  if (s.done() >= cap && !drifting(s)) {
    // Capped but closer to equilibrium: kept, the next step continues (real-time frames).
    // No closer after all the iterations: stalled, rolled back like a divergence. A step
    // capped below kStallIterations is a real-time frame absorbing a new input, whose merit
    // may rise while the next frames continue from it; a runaway is still caught by the
    // blow-up, energy and finiteness checks.
    if (s.merit >= s.start_merit && cap >= kStallIterations) {
      s.fail(stalled(s.merit, s.start_merit, s.done()));
    } else {
      s.result.message = "iteration cap";  // within the string's inline buffer: no allocation per frame
    }
    return true;
  }
  return false;
}

bool NewtonStepper::drifting(const Solve& s) const {
  // Frames far from equilibrium (newton_stepper.h).
  return std::isfinite(solver_.time_budget) && s.result.residual > solver_.capped_residual &&
         s.result.iterations < kRecoveryIterations && Clock::now() < drift_deadline_;
}

Clock::time_point NewtonStepper::deadline_of(int iteration) const {
  return iteration > iteration_cap() ? drift_deadline_ : deadline_;
}

int NewtonStepper::iteration_cap() const {
  return recovering_ ? std::max(solver_.max_iterations, kRecoveryIterations) : solver_.max_iterations;
}

bool NewtonStepper::iteration_out_of_time(Solve& s, bool fresh_factor) {
  // Out of time: the iterate is kept, judged as at the cap (a stall needs kStallIterations
  // iterations to judge). The first iteration of a step always runs, so that every frame moves
  // on. After an iteration of the same stage (a stage's start has moved its instruments), a
  // factorisation that the time left cannot hold starts the next step instead: an iteration
  // and a factorisation in one real-time frame overrun it by the factorisation, and the inputs
  // that arrive meanwhile (clouds, poses) wait or are replaced.
  const Clock::time_point deadline = deadline_of(s.done() + 1);
  if (s.result.iterations == 0 ||
      !(Clock::now() > deadline || (s.done() > 0 && fresh_factor && !factor_.fits(deadline))))
    return false;
  if (s.merit >= s.start_merit && s.done() >= kStallIterations && iteration_cap() >= kStallIterations) {
    s.fail(stalled(s.merit, s.start_merit, s.done()));
  } else {
    s.result.out_of_time = true;
    s.result.message = "time budget";
  }
  return true;
}

bool NewtonStepper::newton_update(UpdateStrategy& update, Solve& s, bool fresh_factor) {
  StepResult& result = s.result;
  if (fresh_factor || update.current_tangent()) matrix_.assemble(result.timing);
  if (!update.prepare(result) || (fresh_factor && !factorize(result))) {
    s.fail("tangent matrix is not positive definite");
    return false;
  }
  const auto t0 = Clock::now();
  // A factorisation costs far more than a Krylov iteration: solve each linearisation well.
  const double forcing = std::clamp(0.1 * solver_.tolerance * s.reference / s.merit, 1e-6, 0.1);
  // The contact problem's share of the force residual the step must reach. In a frame with a
  // time budget, which ends at its cap far from that, no less than a share of the residual the
  // iteration starts from equal to the relative residual (Eisenstat and Walker's quadratic
  // forcing): solved to round-off, 42 of 400 contact solves of the probe cube's 1 ms frames ran
  // to the 1,000-sweep cap (doc/performance.md). Not in converged solves: Gauss-Seidel's change
  // per sweep, which judges the contact problem, understates its error where it converges slowly;
  // nor in a recovery step, which is to converge.
  double force_tolerance = 0.1 * std::max(solver_.tolerance * s.reference, mechanics_.force_floor());
  if (std::isfinite(solver_.time_budget) && !recovering_)
    force_tolerance = std::max(force_tolerance, std::min(0.1, s.merit / s.reference) * s.merit);
  // Captures `this` only: a std::function keeps that without an allocation.
  const Gmres::Operator jacobian = [this](const Eigen::VectorXd& v, Eigen::VectorXd& out) {
    const double h = 1e-8 * mechanics_.length_scale() / std::max(v.cwiseAbs().maxCoeff(), 1e-300);
    x_try_ = x_ + h * v;
    double unused;
    residual(x_try_, out, &unused);
    const std::vector<char>& fixed = mechanics_.fixed_dofs();
    for (int i = 0; i < out.size(); ++i) out[i] = fixed[i] ? v[i] : (r_[i] - out[i]) / h;
  };
  result.linear_iterations += update.solve({r_, forcing, force_tolerance, jacobian, result, deadline_of(s.done())}, dx_);
  result.timing.solve_ms += ms_since(t0);
  if (take_fault(InjectedFault::NonFinite)) dx_[0] = std::numeric_limits<double>::quiet_NaN();
  if (!dx_.allFinite()) {
    s.fail("non-finite Newton update");
    return false;
  }
  return true;
}

bool NewtonStepper::factorize(StepResult& result) {
  if (take_fault(InjectedFault::NotPositiveDefinite)) {
    const std::vector<char>& fixed = mechanics_.fixed_dofs();
    const SparsePattern& pattern = matrix_.pattern();
    for (int i = 0; i < pattern.rows(); ++i)
      if (!fixed[i]) {
        matrix_.values()[pattern.diagonal(i)] = -1;
        break;
      }
  }
  return factor_.factorize(matrix_.values(), result);
}

NewtonStepper::LineSearch NewtonStepper::line_search(const Solve& s, bool contact_update) {
  // Backtracking guards far from the solution. A step is accepted when the merit (free
  // residual and constraint gap) falls enough, or when the potential falls along it: the slope
  // r . dx at the trial point, against the slope at the start, says so (trapezoid rule). The
  // second test keeps full steps that raise the residual only because the linear step
  // over-stretches rotating elements, as in the first step of a bending problem.
  // With the direct contact update the trial point carries the same share of the contact
  // force change: a capped real-time frame then ends where its force balance is (without it,
  // 38 of 300 haptic frames rolled back as stalled). The Krylov update keeps its forces:
  // scaled, its steps took twice the iterations (bench, probe on the cube).
  const auto t0 = Clock::now();
  const std::vector<char>& fixed = mechanics_.fixed_dofs();
  double slope0 = 0;
  for (int i = 0; i < r_.size(); ++i)
    if (!fixed[i]) slope0 += r_[i] * dx_[i];
  // The best norm starts as NaN: a search whose every trial is non-finite ends at the detector.
  LineSearch best{std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(), s.reference,
                  false, 1.0};
  double alpha = 1.0, best_alpha = 1.0;
  const int max_halvings = solver_.line_search ? 6 : 0;
  for (int h = 0;; ++h) {
    x_try_ = x_ + alpha * dx_;
    if (contact_update) contact_.scale_update(alpha);
    const double n_try = residual(x_try_, r_try_, &best.reference);
    const double m_try = merit(n_try, x_try_);
    const bool merit_falls = m_try <= (1.0 - 1e-4 * alpha) * s.merit;
    const bool potential_falls = std::isfinite(m_try) && slope0 > 0 && r_try_.dot(dx_) >= -0.5 * slope0;
    if (merit_falls || potential_falls || m_try < best.merit) {
      best.merit = m_try;
      best.norm = n_try;
      best_alpha = alpha;
    }
    best.accepted = merit_falls || potential_falls;
    if (best.accepted || h == max_halvings) break;
    alpha *= 0.5;
  }
  // None was good enough: take the best one tried.
  best.alpha = best_alpha;
  if (best_alpha != alpha) {
    x_try_ = x_ + best_alpha * dx_;
    if (contact_update) contact_.scale_update(best_alpha);
    best.norm = residual(x_try_, r_try_, &best.reference);
  }
  s.result.timing.assembly_ms += ms_since(t0);
  return best;
}

NewtonStepper::Redo NewtonStepper::redo_on_fresh_factor(Solve& s, bool contact_update, bool descended) {
  // The factor is refactorised at x (evaluated again: the matrix is assembled where the last
  // evaluation was) and the iteration redone. When the factorisation would overrun the time
  // budget, the next iteration or frame starts with it, and this iteration is kept if it
  // descended: a contact update cut short still closed part of its gaps (undone, 14 of the probe
  // cube's 300 frames of 1 ms ended at their prediction: 3.0% error). Else the frame ends where
  // the iteration started.
  factor_.mark_stale();
  const bool fits = factor_.fits(deadline_of(s.done()));
  if (!fits && descended) return Redo::Kept;
  if (contact_update) contact_.scale_update(0.0);
  if (fits) {
    s.refreshed = true;
    --s.result.iterations;
  } else {
    s.result.out_of_time = true;
    s.result.message = "time budget";
  }
  s.norm = residual(x_, r_, &s.reference);  // the evaluation was the trial's
  return fits ? Redo::Redone : Redo::Undone;
}

}  // namespace liver_sim
