// The Newton updates with the contact forces of InstrumentContact (instrument_contact.h) and the
// forces' bookkeeping: the direct update (one solve), the Krylov update
// (krylov_contact_update.h), the line search's scaling, the forces on the tissue.
#include "liver_sim/contact/instrument_contact.h"

namespace liver_sim {

int InstrumentContact::solve_contact_problem(CholmodSolver& factor, const Eigen::VectorXd& r, double force_tolerance) {
  lambda_before_update_.resize(contacts_.size());
  for (size_t c = 0; c < contacts_.size(); ++c) lambda_before_update_[c] = contacts_[c].lambda;
  problem_.build(contacts_, factor, r);
  const int sweeps = problem_.solve(options_, force_tolerance);
  ++solves_;
  return sweeps;
}

InstrumentContact::Update InstrumentContact::direct_update(CholmodSolver& factor, const Eigen::VectorXd& r,
                                                           double force_tolerance, Eigen::VectorXd& dx) {
  Update update;
  update.sweeps = solve_contact_problem(factor, r, force_tolerance);
  const Eigen::VectorXd& lambda = problem_.lambda();
  change_.resize(contacts_.size());
  for (size_t c = 0; c < contacts_.size(); ++c) {
    change_[c] = contacts_[c].frame * (lambda.segment<3>(3 * c) - contacts_[c].lambda);
    contacts_[c].lambda = lambda.segment<3>(3 * c);
  }
  problem_.add_forward(contacts_, change_);
  problem_.backward(factor, dx);
  keep_update();
  return update;
}

InstrumentContact::Update InstrumentContact::krylov_update(CholmodSolver& factor, const Gmres::Operator& jacobian,
                                                           const Eigen::VectorXd& r, double forcing, double force_tolerance,
                                                           Gmres::Clock::time_point deadline, Eigen::VectorXd& dx) {
  Update update;
  // 1. The frictional contact problem with the rows predicted after the tangent's update A^-1 r:
  // which contacts separate, stick or slide. 2. The Newton update for that contact state on the
  // true Jacobian.
  update.sweeps = solve_contact_problem(factor, r, force_tolerance);
  update.krylov =
      krylov_.solve(contacts_, problem_, mechanics_, options_.friction, factor, jacobian, r, forcing, deadline, dx);
  update.relative_residual = krylov_.relative_residual();
  update.out_of_time = krylov_.out_of_time();
  keep_update();
  return update;
}

void InstrumentContact::keep_update() {
  lambda_of_update_.resize(contacts_.size());
  for (size_t c = 0; c < contacts_.size(); ++c) lambda_of_update_[c] = contacts_[c].lambda;
}

void InstrumentContact::scale_update(double alpha) {
  for (size_t c = 0; c < contacts_.size(); ++c)
    contacts_[c].lambda = lambda_before_update_[c] + alpha * (lambda_of_update_[c] - lambda_before_update_[c]);
}

bool InstrumentContact::add_force_change(Eigen::VectorXd& f) const {
  bool changed = false;
  for (size_t c = 0; c < contacts_.size(); ++c) {
    const Contact& contact = contacts_[c];
    const Eigen::Vector3d change = contact.frame * (lambda_of_update_[c] - lambda_before_update_[c]);
    changed |= !change.isZero(0.0);
    for (int n = 0; n < contact.point.count; ++n) f.segment<3>(3 * contact.point.nodes[n]) += contact.point.weights[n] * change;
  }
  return changed;
}

void InstrumentContact::add_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const {
  Eigen::Matrix3d frame;
  for (const Contact& c : contacts_) {
    if (c.lambda.isZero(0.0)) continue;
    contact_rows(c, instruments_[c.instrument], x, x_stage_, &frame);  // the force turns with the instrument's surface at the point
    const Eigen::Vector3d force = frame * c.lambda;
    for (int n = 0; n < c.point.count; ++n) f.segment<3>(3 * c.point.nodes[n]) += c.point.weights[n] * force;
  }
}

Eigen::VectorXd InstrumentContact::forces(const Eigen::VectorXd& x) const {
  Eigen::VectorXd f = Eigen::VectorXd::Zero(x.size());
  add_forces(x, f);
  return f;
}

int InstrumentContact::loaded_contacts() const {
  int n = 0;
  for (const Contact& c : contacts_) n += !c.lambda.isZero(0.0);
  return n;
}

}  // namespace liver_sim
