// The frictional contact problem of one Newton update, ROS-free: the Delassus operator
// W = H A^-1 H^T of the stepper's factorised matrix A at the contacts, their rows predicted after
// the tangent's update A^-1 r, their forces, which are bilateral (held), solved by projected
// Gauss-Seidel (contact_solver.h); and the halves of a solve that let one solve carry the contact
// forces. The compliance between the contacts' nodes is node_compliance.h's, kept while the factor
// lasts; the nodes the scene holds carry nothing.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "liver_sim/contact/node_compliance.h"
#include "liver_sim/contact/surface_contact.h"
#include "liver_sim/linalg/cholmod_solver.h"
#include "liver_sim/model/mechanical_model.h"
#include "liver_sim/scene/options.h"

namespace liver_sim {

class ContactProblem {
 public:
  explicit ContactProblem(const MechanicalModel& mechanics);

  // W, the predicted rows delta = rows + H A^-1 r and the contacts' forces (contact frames), for
  // the contacts and the residual r; the forward half of A^-1 r (forward()).
  void build(const std::vector<SurfaceContact>& contacts, CholmodSolver& factor, const Eigen::VectorXd& r);
  // Projected Gauss-Seidel from the contacts' forces until the gaps carry a force error below
  // force_tolerance (N), and to 1% of options.tolerance at least: the new forces in lambda().
  // Returns the sweeps.
  int solve(const ContactOptions& options, double force_tolerance);
  const Eigen::VectorXd& lambda() const { return lambda_; }  // 3 per contact, in its frame (N)

  // G_pq = E_p^T A^-1 E_q between two surface points through their free nodes (m/N).
  Eigen::Matrix3d compliance(const SurfacePoint& p, const SurfacePoint& q) const;
  // The forward half z = L^-1 P b of A^-1 b, and its motion at the contacts' free nodes.
  void forward(CholmodSolver& factor, const Eigen::VectorXd& b);
  // The motion A^-1 b at p, for the b of the last forward().
  Eigen::Vector3d motion(const SurfacePoint& p) const;
  // z += the forward half of force changes at the contacts (world frame, one per contact).
  void add_forward(const std::vector<SurfaceContact>& contacts, const std::vector<Eigen::Vector3d>& change);
  // x = the backward half of z: A^-1 of what was put forward.
  void backward(CholmodSolver& factor, Eigen::VectorXd& x);

  long compliance_columns() const { return compliance_.columns(); }

 private:
  // The gap tolerance of the Gauss-Seidel solve for a force tolerance (N).
  double gap_tolerance(const ContactOptions& options, double force_tolerance) const;

  const MechanicalModel& mechanics_;
  NodeCompliance compliance_;
  std::vector<int> free_nodes_;                 // the contacts' nodes not held by the scene
  std::vector<Eigen::Vector3d> node_vector_;    // per node: E^T A^-1 b, or a force change
  std::vector<char> node_marked_;
  Eigen::VectorXd z_;
  Eigen::MatrixXd W_;
  Eigen::VectorXd delta_, lambda_;
  std::vector<char> bilateral_;
};

inline Eigen::Matrix3d ContactProblem::compliance(const SurfacePoint& p, const SurfacePoint& q) const {
  Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
  for (int j = 0; j < p.count; ++j) {
    if (mechanics_.fixed_by_scene(p.nodes[j])) continue;
    for (int k = 0; k < q.count; ++k)
      if (!mechanics_.fixed_by_scene(q.nodes[k]))
        G += (p.weights[j] * q.weights[k]) * compliance_.block(p.nodes[j], q.nodes[k]);
  }
  return G;
}

}  // namespace liver_sim
