// Vessels: corotational 3D Euler-Bernoulli beams with a hollow circular section. Each node has a
// position and a rotation (rest: identity). An element measures its deformation in a frame that
// follows it: the x axis along the current chord, the y axis from the mean of the two nodal
// rotations; in that frame it is the linear beam (axial, torsion, two bending planes), so rigid
// motions give exactly zero force and large rotations are handled by the frame.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "liver_sim/model/corotational_tetra.h"

namespace liver_sim {

// Rotation vector <-> rotation matrix, and the left Jacobian of exp: for R = exp(w), a change
// dw rotates R by the spatial angle left_jacobian(w) dw.
Eigen::Matrix3d rotation_exp(const Eigen::Vector3d& w);
Eigen::Vector3d rotation_log(const Eigen::Matrix3d& R);
Eigen::Matrix3d left_jacobian(const Eigen::Vector3d& w);

struct BeamSection {
  double outer_radius = 0;    // m
  double wall_thickness = 0;  // m, 0 < t <= outer_radius (t = radius: a solid rod)
  double young_modulus = 0;   // Pa
  double poisson_ratio = 0;   // -
  double area() const;            // m^2
  double second_moment() const;   // m^4, about a diameter (I_y = I_z; polar J = 2 I)
};

class CorotationalBeams {
 public:
  // X: rest positions of the beam nodes (#nodes x 3, m); segments: node pairs; one section per
  // segment.
  CorotationalBeams(const Eigen::MatrixX3d& X, const Eigen::MatrixX2i& segments,
                    const std::vector<BeamSection>& sections);

  // Updates the element frames and local deformations from node positions p (3 #nodes,
  // node-major) and node rotations R.
  void update_frames(const Eigen::VectorXd& p, const std::vector<Eigen::Matrix3d>& R);

  // Internal force of element e, [f_a, m_a, f_b, m_b] (N, N m, world frame; moments are
  // conjugate to spatial rotation increments), and its tangent T^T K_local T (the derivative of
  // the element frame is dropped, as for the tetrahedra); from the last update_frames.
  void element_force(int e, Vector12d& f) const;
  void element_tangent(int e, Matrix12d& K) const;
  double element_energy(int e) const { return 0.5 * local_deformation_[e].dot(local_force_[e]); }  // J

  int size() const { return static_cast<int>(L_.size()); }
  const Eigen::MatrixX2i& segments() const { return segments_; }

 private:
  Eigen::MatrixX2i segments_;
  std::vector<double> L_;
  std::vector<Eigen::Matrix3d> rest_frame_;  // columns: chord, then two section axes
  std::vector<Matrix12d> K_local_;
  std::vector<Eigen::Matrix3d> frame_;       // current element frame
  std::vector<Vector12d> local_deformation_;  // d_local of the last update
  std::vector<Vector12d> local_force_;        // K_local d_local
};

}  // namespace liver_sim
