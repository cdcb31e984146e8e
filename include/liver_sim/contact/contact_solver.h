// The frictional contact problem on the Delassus (compliance) operator, solved by projected
// Gauss-Seidel over contacts (Duriez et al. 2006, the reference model's solver). ROS-free.
//
// Each contact has three rows: the normal gap and two tangential slips (m). With the forces
// lambda (N, normal first) the rows move as  delta = delta0 + W (lambda - lambda_start).
// Unilateral contacts obey Signorini and Coulomb: delta_n >= 0, lambda_n >= 0, delta_n lambda_n
// = 0; |lambda_t| <= mu lambda_n, sticking (delta_t = 0) inside the cone and sliding against
// delta_t on its edge. Bilateral contacts (grasped nodes) hold all three rows at zero.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace liver_sim {

struct ContactSolveResult {
  int sweeps = 0;
  double last_change = 0;  // m: largest gap change of one contact's update in the last sweep
  bool converged = false;
};

// lambda holds the start forces on entry (warm start) and the solution on exit.
ContactSolveResult solve_frictional_contacts(const Eigen::MatrixXd& W, const Eigen::VectorXd& delta0,
                                             const std::vector<char>& bilateral, double friction,
                                             double tolerance, int max_sweeps, Eigen::VectorXd& lambda);

}  // namespace liver_sim
