// The Newton updates with the contact forces of InstrumentContact (instrument_contact.h) and the
// forces' bookkeeping: the direct update (one solve), the Krylov update
// (krylov_contact_update.h), the line search's scaling, the forces on the tissue.
#include "liver_sim/contact/instrument_contact.h"

#include "liver_sim/contact/instrument_shape.h"

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

bool InstrumentContact::add_turning_stiffness(const Eigen::VectorXd& x, std::vector<double>& values) const {
  // A contact's force F(p) lambda turns with the instrument's surface at its point p: at a
  // point of a sphere of radius R, d(F lambda)/dp = lambda_n (I - n n^T) / R (frictionless).
  // Without this term the linearisation is stiffer than the problem across the normal (a
  // frictionless indenter lets the tissue slide off its curve), and Newton's iterations only
  // contract by about lambda_n / R over the tissue's stiffness there. Derivative by central
  // differences of the surface's frame (every shape), symmetrised for the Cholesky factor.
  const SparsePattern& pattern = mechanics_.pattern();
  const std::vector<char>& fixed = mechanics_.fixed_dofs();
  bool added = false;
  for (const Contact& c : contacts_) {
    if (c.held >= 0 || c.lambda.isZero(0.0)) continue;
    const InstrumentSlot& in = instruments_[c.instrument];
    const InstrumentShape& shape = shape_of(in.options.type);
    const Eigen::Vector3d p = c.point.at(x);
    const double h = 1e-4 * shape.size(in.options);
    Eigen::Matrix3d turning;  // d(F lambda)/dp
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(k);
      turning.col(k) = (surface_frame(shape.distance(in.options, in.pose, p + e).normal) -
                        surface_frame(shape.distance(in.options, in.pose, p - e).normal)) *
                       c.lambda / (2 * h);
    }
    // The matrix is -d(residual)/dx, and the force adds to the residual.
    const Eigen::Matrix3d stiffness = -0.5 * (turning + turning.transpose());
    for (int a = 0; a < c.point.count; ++a)
      for (int b = 0; b < c.point.count; ++b)
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            const int row = 3 * c.point.nodes[a] + i, col = 3 * c.point.nodes[b] + j;
            if (row > col || fixed[row] || fixed[col]) continue;
            const int entry = pattern.find(row, col);
            if (entry >= 0) values[entry] += c.point.weights[a] * c.point.weights[b] * stiffness(i, j);
          }
    added = true;
  }
  return added;
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
