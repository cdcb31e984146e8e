// The Newton update with contacts on the true Jacobian J, ROS-free (Newton-Krylov's contact
// update): for the contact state the contact problem decided (contact_problem.h), GMRES on
//      J dx - B lambda = r_free,   H dx = -rows
// (sticking and held contacts: three rows and forces along the frame; sliding: the normal row,
// and a force along n + mu t on the cone's edge; separating: none), preconditioned by the same
// system with the factorised tangent A: lambda = S^-1 (g - H A^-1 u), dx = A^-1 (u + B lambda),
// S = H A^-1 B, each application one forward and one backward half solve.
#pragma once

#include <Eigen/Core>
#include <Eigen/QR>
#include <vector>

#include "liver_sim/contact/contact_problem.h"
#include "liver_sim/contact/surface_contact.h"
#include "liver_sim/linalg/cholmod_solver.h"
#include "liver_sim/linalg/gmres.h"
#include "liver_sim/model/mechanical_model.h"

namespace liver_sim {

class KrylovContactUpdate {
 public:
  // dx for the residual r (the free forces plus the contacts' current forces), with the problem
  // built and solved for r; sets the contacts' forces. Returns the GMRES iterations; GMRES stops
  // at the deadline with its iterate so far (Gmres::solve), forces and motion together.
  int solve(std::vector<SurfaceContact>& contacts, ContactProblem& problem, const MechanicalModel& mechanics,
            double friction, CholmodSolver& factor, const Gmres::Operator& jacobian, const Eigen::VectorXd& r,
            double forcing, Gmres::Clock::time_point deadline, Eigen::VectorXd& dx);
  double relative_residual() const { return gmres_.relative_residual(); }  // GMRES's at the end
  bool out_of_time() const { return gmres_.out_of_time(); }  // GMRES stopped at the deadline

 private:
  struct Unknown {  // one force unknown
    int contact;
    Eigen::Vector3d row;     // its constraint row at the point (dx . row = target)
    Eigen::Vector3d force;   // the force per unit unknown at the point
    double target;
  };
  // The unknowns of the contact state that the contact problem's forces (contact frames) decide:
  // sticking and held contacts three, sliding ones one, separating ones none.
  void choose_unknowns(const std::vector<SurfaceContact>& contacts, const Eigen::VectorXd& lambda, double friction);

  std::vector<Unknown> unknowns_;
  Eigen::MatrixXd schur_;
  // Points close together on few nodes (a shaft lying along a face) make dependent rows: the
  // least-norm solution of the Schur system.
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> schur_solver_;
  Eigen::VectorXd augmented_rhs_, augmented_solution_, augmented_dx_, augmented_out_, schur_rhs_, schur_solution_;
  std::vector<Eigen::Vector3d> change_;
  Gmres gmres_;
};

}  // namespace liver_sim
