// Parenchyma: corotational linear tetrahedra. Rest stiffness K0 = V B^T D B per element is
// computed once; each evaluation extracts the element rotation R from the current shape and
// gives f = R K0 (R^T x - X) and the tangent R K0 R^T (the derivative of R is dropped, as usual).
#pragma once

#include <Eigen/Core>
#include <vector>

#include "liver_sim/options.h"

namespace liver_sim {

using Matrix12d = Eigen::Matrix<double, 12, 12>;
using Vector12d = Eigen::Matrix<double, 12, 1>;

// The matrix of w x . (cross product with w).
Eigen::Matrix3d cross_matrix(const Eigen::Vector3d& w);

// Rotation of the polar decomposition F = R S (a proper rotation also for inverted F).
Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& F);
// d theta / d x (3 x 12): the spatial rotation increment of R = polar_rotation(F) per change of
// the tetrahedron's 4 node positions, for F = [x1-x0, x2-x0, x3-x0] Dm_inv.
Eigen::Matrix<double, 3, 12> polar_rotation_derivative(const Eigen::Matrix3d& R, const Eigen::Matrix3d& F,
                                                      const Eigen::Matrix3d& Dm_inv);

class CorotationalTetra {
 public:
  // X: rest positions (#V x 3, m); T: positively oriented tetrahedra.
  CorotationalTetra(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T,
                    const ParenchymaOptions& material);

  // Recomputes K0 for a new modulus / Poisson ratio (no other state changes).
  void set_material(const ParenchymaOptions& material);

  // Updates the rotation of every element from current positions x (3 #V, node-major).
  void update_rotations(const Eigen::VectorXd& x);

  // Element internal force (12, the force the element needs to be held in shape x) and
  // tangent, using the rotation from the last update_rotations. element_force returns the
  // strain energy 1/2 u^T K0 u of the corotated displacement (J).
  double element_force(int e, const Eigen::VectorXd& x, Vector12d& f) const;
  void element_tangent(int e, Matrix12d& K) const;

  // Rotation of element e from the last update; rest stiffness; rest volume (m^3).
  const Eigen::Matrix3d& rotation(int e) const { return R_[e]; }
  const Matrix12d& rest_stiffness(int e) const { return K0_[e]; }
  double volume(int e) const { return volume_[e]; }
  int size() const { return static_cast<int>(K0_.size()); }
  const Eigen::MatrixX4i& elements() const { return T_; }

  // Inverse rest edge matrix [X1-X0, X2-X0, X3-X0]^-1, and F = [x1-x0, x2-x0, x3-x0] times it.
  const Eigen::Matrix3d& rest_edge_inverse(int e) const { return Dm_inv_[e]; }
  Eigen::Matrix3d deformation_gradient(int e, const Eigen::VectorXd& x) const;

  // Strain in the element's rotated frame, sym(R^T F) - I (Voigt-free 3x3), for tests and output.
  Eigen::Matrix3d corotated_strain(int e, const Eigen::VectorXd& x) const;

 private:
  Eigen::Matrix3d rotation_geometric(int e, const Eigen::VectorXd& x) const;
  Eigen::Matrix3d rotation_polar(int e, const Eigen::VectorXd& x) const;
  // R^T x - X per node, relative to node 0, with the rotation of the last update.
  Vector12d corotated_displacement(int e, const Eigen::VectorXd& x) const;

  Eigen::MatrixX4i T_;
  RotationMethod method_;
  std::vector<Vector12d> X_;  // rest positions of the 4 nodes
  std::vector<Eigen::Matrix3d> Dm_inv_;         // inverse rest edge matrix
  std::vector<Eigen::Matrix3d> rest_frame_T_;   // transposed edge frame of the rest shape
  std::vector<Eigen::Matrix<double, 4, 3>> grad_N_;  // shape-function gradients (1/m)
  std::vector<double> volume_;
  std::vector<Matrix12d> K0_;
  std::vector<Eigen::Matrix3d> R_;
};

}  // namespace liver_sim
