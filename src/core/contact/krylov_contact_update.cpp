#include "liver_sim/contact/krylov_contact_update.h"

namespace liver_sim {
namespace {

constexpr int kMaxKrylov = 30;  // GMRES iterations per Newton update

}  // namespace

void KrylovContactUpdate::choose_unknowns(const std::vector<SurfaceContact>& contacts, const Eigen::VectorXd& lambda_all,
                                          double friction) {
  unknowns_.clear();
  const int m = static_cast<int>(contacts.size());
  for (int c = 0; c < m; ++c) {
    const SurfaceContact& contact = contacts[c];
    const Eigen::Vector3d lambda = lambda_all.segment<3>(3 * c);
    const double cone = friction * lambda[0];
    if (contact.held >= 0 || (lambda[0] > 0 && friction > 0 && lambda.tail<2>().norm() < cone * (1 - 1e-9))) {
      for (int k = 0; k < 3; ++k) unknowns_.push_back({c, contact.frame.col(k), contact.frame.col(k), -contact.rows[k]});
    } else if (lambda[0] > 0) {
      Eigen::Vector3d direction = contact.frame.col(0);
      if (friction > 0) direction += contact.frame.rightCols<2>() * (lambda.tail<2>() / lambda[0]);
      unknowns_.push_back({c, contact.frame.col(0), direction, -contact.rows[0]});
    }
  }
}

int KrylovContactUpdate::solve(std::vector<SurfaceContact>& contacts, ContactProblem& problem,
                               const MechanicalModel& mechanics, double friction, CholmodSolver& factor,
                               const Gmres::Operator& jacobian, const Eigen::VectorXd& r, double forcing,
                               Gmres::Clock::time_point deadline, Eigen::VectorXd& dx) {
  choose_unknowns(contacts, problem.lambda(), friction);
  const int k = static_cast<int>(unknowns_.size());
  const std::vector<char>& fixed = mechanics.fixed_dofs();
  // The point's motion or force through its free nodes.
  const auto point_of = [&](const SurfacePoint& p, const Eigen::VectorXd& v) {
    Eigen::Vector3d s = Eigen::Vector3d::Zero();
    for (int j = 0; j < p.count; ++j)
      if (!mechanics.fixed_by_scene(p.nodes[j])) s += p.weights[j] * v.segment<3>(3 * p.nodes[j]);
    return s;
  };
  schur_.resize(k, k);
  for (int a = 0; a < k; ++a) {
    const SurfacePoint& pa = contacts[unknowns_[a].contact].point;
    for (int b = 0; b < k; ++b) {
      const SurfacePoint& pb = contacts[unknowns_[b].contact].point;
      schur_(a, b) = unknowns_[a].row.dot(problem.compliance(pa, pb) * unknowns_[b].force);
    }
  }
  schur_solver_.setThreshold(1e-10);
  if (k > 0) schur_solver_.compute(schur_);  // (Eigen's decomposition fails on an empty matrix)
  const Eigen::Index dofs = r.size();
  augmented_rhs_.resize(dofs + k);
  augmented_rhs_.head(dofs) = r;
  for (const SurfaceContact& c : contacts) {  // the free forces: r without the contact forces
    const Eigen::Vector3d force = c.frame * c.lambda;
    for (int j = 0; j < c.point.count; ++j) augmented_rhs_.segment<3>(3 * c.point.nodes[j]) -= c.point.weights[j] * force;
  }
  for (Eigen::Index i = 0; i < dofs; ++i)
    if (fixed[i]) augmented_rhs_[i] = 0;
  for (int a = 0; a < k; ++a) augmented_rhs_[dofs + a] = unknowns_[a].target;
  const Gmres::Operator system = [&](const Eigen::VectorXd& z, Eigen::VectorXd& out) {
    augmented_dx_ = z.head(dofs);
    jacobian(augmented_dx_, augmented_out_);
    out.resize(dofs + k);
    out.head(dofs) = augmented_out_;
    for (int a = 0; a < k; ++a) {
      const SurfacePoint& p = contacts[unknowns_[a].contact].point;
      for (int j = 0; j < p.count; ++j)
        if (!mechanics.fixed_by_scene(p.nodes[j]))
          out.segment<3>(3 * p.nodes[j]) -= p.weights[j] * unknowns_[a].force * z[dofs + a];
      out[dofs + a] = unknowns_[a].row.dot(point_of(p, z));
    }
  };
  const Gmres::Operator preconditioner = [&](const Eigen::VectorXd& in, Eigen::VectorXd& out) {
    augmented_dx_ = in.head(dofs);
    problem.forward(factor, augmented_dx_);
    schur_rhs_.resize(k);
    for (int a = 0; a < k; ++a)
      schur_rhs_[a] = in[dofs + a] - unknowns_[a].row.dot(problem.motion(contacts[unknowns_[a].contact].point));
    schur_solution_ = k > 0 ? Eigen::VectorXd(schur_solver_.solve(schur_rhs_)) : Eigen::VectorXd();
    change_.assign(contacts.size(), Eigen::Vector3d::Zero());
    for (int a = 0; a < k; ++a) change_[unknowns_[a].contact] += unknowns_[a].force * schur_solution_[a];
    problem.add_forward(contacts, change_);
    problem.backward(factor, augmented_out_);
    out.resize(dofs + k);
    out.head(dofs) = augmented_out_;
    out.tail(k) = schur_solution_;
  };
  const int iterations =
      gmres_.solve(system, preconditioner, augmented_rhs_, augmented_solution_, forcing, kMaxKrylov, deadline);
  dx = augmented_solution_.head(dofs);
  change_.assign(contacts.size(), Eigen::Vector3d::Zero());
  for (int a = 0; a < k; ++a) change_[unknowns_[a].contact] += unknowns_[a].force * augmented_solution_[dofs + a];
  for (size_t c = 0; c < contacts.size(); ++c) contacts[c].lambda = contacts[c].frame.transpose() * change_[c];
  return iterations;
}

}  // namespace liver_sim
