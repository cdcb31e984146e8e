// Glisson's capsule: corotational constant-strain-triangle membranes on boundary triangles,
// plane stress, thickness h, sharing the tetrahedra's nodes. The in-plane rotation comes from
// the polar decomposition of the 2D deformation gradient, so the result does not depend on the
// vertex order of a triangle.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "liver_sim/model/lanes.h"
#include "liver_sim/scene/options.h"

namespace liver_sim {

using Matrix9d = Eigen::Matrix<double, 9, 9>;
using Vector9d = Eigen::Matrix<double, 9, 1>;

class MembraneCST {
 public:
  // X: rest positions (#V x 3, m); F: triangles (#F x 3).
  MembraneCST(const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& F, const CapsuleOptions& material);

  // Rescales the stiffness for a new E, h, nu (no geometry is recomputed).
  void set_material(const CapsuleOptions& material);

  // Updates the in-plane frame of every triangle from current positions x (3 #V).
  void update_rotations(const Eigen::VectorXd& x) { update_rotations(x, 0, size()); }
  // The same for triangles first .. first + count - 1, four at a time from first (a multiple of
  // 4): a loop split at multiples of 4 gives the frames of the whole loop to the last bit.
  void update_rotations(const Eigen::VectorXd& x, int first, int count);
  double element_force(int e, const Eigen::VectorXd& x, Vector9d& f) const;  // returns 1/2 u^T K u (J)
  void element_tangent(int e, Matrix9d& K) const;
  // A K A^T v_e for a given in-plane frame A (3x2): the damping force with the stiffness of an
  // earlier state, without assembling it.
  void tangent_product(int e, const Eigen::Matrix<double, 3, 2>& A, const Eigen::VectorXd& v, Vector9d& out) const;
  const std::vector<Eigen::Matrix<double, 3, 2>>& frames() const { return frame_; }
  void restore_frames(const std::vector<Eigen::Matrix<double, 3, 2>>& frames) { frame_ = frames; }  // saved from frames()

  // Small-strain corotated in-plane strain, sym(R^T F) - I (2x2) of triangle e, for tests.
  Eigen::Matrix2d corotated_strain(int e, const Eigen::VectorXd& x) const;

  int size() const { return static_cast<int>(F_.rows()); }
  const Eigen::MatrixX3i& triangles() const { return F_; }
  double area(int e) const { return area_[e]; }

 private:
  // Current frame: columns are the two in-plane axes, rotated so that rest 2D coordinates map
  // onto the current triangle (3x2).
  Eigen::Matrix<double, 3, 2> current_frame(int e, const Eigen::VectorXd& x) const;
  // The same for triangles first .. first + 3 (first a multiple of 4) at once, vectorized across
  // them (as the tetrahedra's kernels), into frame_.
  void update_frames(int first, const Eigen::VectorXd& x);
  // In-plane displacement in the rotated frame of the last update (6: 2 per node).
  Eigen::Matrix<double, 6, 1> corotated_displacement(int e, const Eigen::VectorXd& x) const;

  Eigen::MatrixX3i F_;
  std::vector<Eigen::Matrix<double, 3, 2>> p_;     // rest 2D coordinates (rows)
  std::vector<Eigen::Matrix2d> Pm_inv_;            // inverse rest 2D edge matrix
  std::vector<Lanes> Pm_inv_blocks_;               // Pm_inv_ (i, j) of triangles 4 b .. 4 b + 3 at 4 b + 2 i + j
  std::vector<Eigen::Matrix<double, 3, 2>> grad_N_;
  std::vector<double> area_;
  std::vector<Eigen::Matrix<double, 6, 6>> K2_;    // in-plane stiffness, 2D local frame
  std::vector<Eigen::Matrix<double, 3, 2>> frame_; // from the last update_rotations
};

}  // namespace liver_sim
