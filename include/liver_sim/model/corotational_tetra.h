// Parenchyma: corotational linear tetrahedra. Rest stiffness K0 = V B^T D B per element is
// computed once; each evaluation extracts the element rotation R from the current shape and
// gives f = R K0 (R^T x - X) and the tangent R K0 R^T (the derivative of R is dropped, as usual).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <vector>

#include "liver_sim/model/lanes.h"
#include "liver_sim/scene/options.h"

namespace liver_sim {

using Matrix12d = Eigen::Matrix<double, 12, 12>;
using Vector12d = Eigen::Matrix<double, 12, 1>;

// The matrix of w x . (cross product with w).
Eigen::Matrix3d cross_matrix(const Eigen::Vector3d& w);

// Rotation of the polar decomposition F = R S (a proper rotation also for inverted F; NaN for a
// non-finite F).
Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& F);
// The same, iterated from a nearby rotation q (the element's last one), which it updates:
// about 3x faster when q is close, the same result to round-off.
Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& F, Eigen::Quaterniond& q);
// The same for four elements at once, each from its own q: up to two steps vectorized across
// them, the iteration above for any that they leave unconverged. Same results to round-off.
void polar_rotations(const std::array<Eigen::Matrix3d, 4>& F, const std::array<Eigen::Quaterniond*, 4>& q,
                     std::array<Eigen::Matrix3d, 4>& R);
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
  // Back to the rest rotations (identity), where the polar iterations start: a model that is
  // reset repeats its tissue results to the last bit.
  void reset_rotations();
  // Before a dynamic step's first evaluation at a predicted state, with the rotations of the
  // step's start current: the polar iterations start from them continued at constant angular
  // velocity, R_n R_n-1^T R_n, where R_n-1 were current at the last call, if that call was one
  // step ago (continued); else they are only recorded. The guesses change, the results do not
  // (to round-off): one iteration then suffices where the rotation changed by more than ~1e-5.
  void predict_rotations(bool continued);
  // The rotations and the polar iterations' warm starts, saved and restored as one (a step that
  // is rolled back leaves them as they were before it, to the last bit).
  struct RotationState {
    std::vector<Eigen::Matrix3d> R;
    std::vector<Eigen::Quaterniond> q, q_step;
  };
  void save_rotations(RotationState& s) const {
    s.R = R_;
    s.q = q_;
    s.q_step = q_step_;
  }
  void restore_rotations(const RotationState& s) {
    R_ = s.R;
    q_ = s.q;
    q_step_ = s.q_step;
  }

  // Element internal force (12, the force the element needs to be held in shape x); updates
  // the element's rotation to x first. Returns the strain energy 1/2 u^T K0 u of the corotated
  // displacement (J).
  double element_force(int e, const Eigen::VectorXd& x, Vector12d& f);
  // The same for elements first .. first + count - 1 (count <= 4), four at once from a multiple
  // of 4 (one at a time otherwise); returns their summed energy.
  double element_forces(int first, int count, const Eigen::VectorXd& x, Vector12d* f);
  // Tangent R K0 R^T with the rotation of the last update.
  void element_tangent(int e, Matrix12d& K) const;
  // R K0 R^T v_e for a given rotation R (a velocity v, 3 #V): the damping force b K v with the
  // stiffness of an earlier state, without assembling it.
  void tangent_product(int e, const Eigen::Matrix3d& R, const Eigen::VectorXd& v, Vector12d& out) const;
  // The same for elements first .. first + count - 1 (as element_forces), R indexed by element.
  void tangent_products(int first, int count, const std::vector<Eigen::Matrix3d>& R, const Eigen::VectorXd& v,
                        Vector12d* out) const;

  // Rotation of element e from the last update; rest stiffness; rest volume (m^3).
  const Eigen::Matrix3d& rotation(int e) const { return R_[e]; }
  const std::vector<Eigen::Matrix3d>& rotations() const { return R_; }
  // Where element e's next polar iteration starts (for tests).
  const Eigen::Quaterniond& rotation_guess(int e) const { return q_[e]; }
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
  void update_rotation(int e, const Eigen::VectorXd& x, const Eigen::Matrix3d& F);
  // Stress (Pa) in the element's frame for a displacement gradient G there (linear elasticity).
  Eigen::Matrix3d rotated_stress(const Eigen::Matrix3d& G) const;
  // Nodal forces V P g_a of a stress P in world axes.
  void nodal_forces(int e, const Eigen::Matrix3d& P, Vector12d& f) const;
  // Four at once, from element first (a multiple of 4): F = Ds Dm^-1 of positions (or
  // velocities) x; the forces V R sigma(G) g_a of a gradient G in the elements' frames, returning
  // the energies 1/2 V sigma : G.
  LaneMatrix lane_gradient(int first, const Eigen::VectorXd& x) const;
  Lanes lane_forces(int first, const LaneMatrix& R, const LaneMatrix& G, Vector12d* f) const;

  Eigen::MatrixX4i T_;
  RotationMethod method_;
  std::vector<Eigen::Matrix3d> Dm_inv_;         // inverse rest edge matrix
  std::vector<Eigen::Matrix3d> rest_frame_T_;   // transposed edge frame of the rest shape
  std::vector<Eigen::Matrix<double, 4, 3>> grad_N_;  // shape-function gradients (1/m)
  std::vector<double> volume_;
  struct Block {  // Dm_inv_ and volume_ of elements 4 b .. 4 b + 3, side by side
    LaneMatrix Dm_inv;
    Lanes volume;
  };
  std::vector<Block> blocks_;
  std::vector<Matrix12d> K0_;  // for the tangent; forces use the stress (rotated_stress)
  double lambda_ = 0, mu_ = 0;   // Lame parameters (Pa)
  std::vector<Eigen::Matrix3d> R_;
  std::vector<Eigen::Quaterniond> q_;  // R_ as a unit quaternion: where the next polar iteration starts
  std::vector<Eigen::Quaterniond> q_step_;  // q_ at the last predict_rotations (the previous step's start)
};

}  // namespace liver_sim
