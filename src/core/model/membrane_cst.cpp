#include "liver_sim/model/membrane_cst.h"


#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>

#include "liver_sim/geometry/node_positions.h"

namespace liver_sim {
namespace {

// Two orthonormal in-plane axes (columns): the first edge and its normal in the plane.
Eigen::Matrix<double, 3, 2> plane_axes(const Eigen::Vector3d& e01, const Eigen::Vector3d& e02) {
  const Eigen::Vector3d a = e01.normalized();
  const Eigen::Vector3d n = e01.cross(e02).normalized();
  Eigen::Matrix<double, 3, 2> axes;
  axes << a, n.cross(a);
  return axes;
}

}  // namespace

MembraneCST::MembraneCST(const Eigen::MatrixX3d& X, const Eigen::MatrixX3i& F,
                         const CapsuleOptions& material)
    : F_(F) {
  const int n = static_cast<int>(F.rows());
  p_.resize(n);
  Pm_inv_.resize(n);
  grad_N_.resize(n);
  area_.resize(n);
  frame_.resize(n);
  for (int e = 0; e < n; ++e) {
    const Eigen::Vector3d X0 = X.row(F(e, 0)).transpose();
    const Eigen::Vector3d e01 = X.row(F(e, 1)).transpose() - X0;
    const Eigen::Vector3d e02 = X.row(F(e, 2)).transpose() - X0;
    const Eigen::Matrix<double, 3, 2> axes = plane_axes(e01, e02);
    frame_[e] = axes;
    for (int i = 0; i < 3; ++i)
      p_[e].row(i) = (axes.transpose() * (X.row(F(e, i)).transpose() - X0)).transpose();
    Eigen::Matrix2d Pm;
    Pm << (p_[e].row(1) - p_[e].row(0)).transpose(), (p_[e].row(2) - p_[e].row(0)).transpose();
    area_[e] = 0.5 * Pm.determinant();
    Pm_inv_[e] = Pm.inverse();
    grad_N_[e].bottomRows<2>() = Pm_inv_[e];
    grad_N_[e].row(0) = -Pm_inv_[e].colwise().sum();
  }
  Pm_inv_blocks_.resize(n / 4 * 4);
  for (int b = 0; b < n / 4; ++b)
    for (int k = 0; k < 4; ++k) {
      const int e = 4 * b;
      const int i = k / 2, j = k % 2;
      Pm_inv_blocks_[4 * b + k] = Lanes(Pm_inv_[e](i, j), Pm_inv_[e + 1](i, j), Pm_inv_[e + 2](i, j), Pm_inv_[e + 3](i, j));
    }
  set_material(material);
}

void MembraneCST::set_material(const CapsuleOptions& material) {
  const double E = material.young_modulus, nu = material.poisson_ratio, h = material.thickness;
  // Plane stress: sigma = lambda* tr(eps) I + 2 mu eps, lambda* = E nu / (1 - nu^2).
  const double lambda = E * nu / (1 - nu * nu);
  const double mu = E / (2 * (1 + nu));
  K2_.resize(area_.size());
  for (size_t e = 0; e < area_.size(); ++e) {
    for (int a = 0; a < 3; ++a) {
      const Eigen::Vector2d ga = grad_N_[e].row(a).transpose();
      for (int b = 0; b < 3; ++b) {
        const Eigen::Vector2d gb = grad_N_[e].row(b).transpose();
        K2_[e].block<2, 2>(2 * a, 2 * b) =
            h * area_[e] * (lambda * ga * gb.transpose() + mu * gb * ga.transpose() +
                            mu * ga.dot(gb) * Eigen::Matrix2d::Identity());
      }
    }
  }
}

Eigen::Matrix<double, 3, 2> MembraneCST::current_frame(int e, const Eigen::VectorXd& x) const {
  const Eigen::Vector3d x0 = node(x, F_(e, 0));
  const Eigen::Matrix<double, 3, 2> axes =
      plane_axes(node(x, F_(e, 1)) - x0, node(x, F_(e, 2)) - x0);
  // In-plane deformation gradient in these axes, then its rotation (2D polar decomposition in
  // closed form) so that the frame follows the triangle, not its first edge.
  Eigen::Matrix2d Q;
  Q << axes.transpose() * (node(x, F_(e, 1)) - x0), axes.transpose() * (node(x, F_(e, 2)) - x0);
  const Eigen::Matrix2d F2 = Q * Pm_inv_[e];
  // The rotation angle is atan2(F10 - F01, F00 + F11); its cosine and sine without trigonometry.
  const double c = F2(0, 0) + F2(1, 1), s = F2(1, 0) - F2(0, 1), r = std::sqrt(c * c + s * s);
  Eigen::Matrix2d R2 = Eigen::Matrix2d::Identity();
  if (r > 0) R2 << c / r, -s / r, s / r, c / r;
  return axes * R2;
}

void MembraneCST::update_frames(int first, const Eigen::VectorXd& x) {
  Lanes e1[3], e2[3];  // the edges from node 0 to nodes 1 and 2
  for (int l = 0; l < 4; ++l) {
    const Eigen::Vector3d x0 = node(x, F_(first + l, 0));
    const Eigen::Vector3d d1 = node(x, F_(first + l, 1)) - x0, d2 = node(x, F_(first + l, 2)) - x0;
    for (int i = 0; i < 3; ++i) {
      e1[i][l] = d1[i];
      e2[i][l] = d2[i];
    }
  }
  // plane_axes: a along the first edge, b = n x a in the plane.
  const Lanes edge2 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2];
  Lanes n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
  const Lanes normal2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
  const Lanes inv_edge = 1.0 / edge2.sqrt(), inv_normal = 1.0 / normal2.sqrt();
  Lanes a[3], b[3];
  for (int i = 0; i < 3; ++i) {
    a[i] = e1[i] * inv_edge;
    n[i] *= inv_normal;
  }
  b[0] = n[1] * a[2] - n[2] * a[1];
  b[1] = n[2] * a[0] - n[0] * a[2];
  b[2] = n[0] * a[1] - n[1] * a[0];
  // The in-plane gradient F2 = Q Pm^-1 and its rotation, as current_frame.
  const Lanes q00 = a[0] * e1[0] + a[1] * e1[1] + a[2] * e1[2], q01 = a[0] * e2[0] + a[1] * e2[1] + a[2] * e2[2];
  const Lanes q10 = b[0] * e1[0] + b[1] * e1[1] + b[2] * e1[2], q11 = b[0] * e2[0] + b[1] * e2[1] + b[2] * e2[2];
  const Lanes* P = &Pm_inv_blocks_[first];
  const Lanes f00 = q00 * P[0] + q01 * P[2], f01 = q00 * P[1] + q01 * P[3];
  const Lanes f10 = q10 * P[0] + q11 * P[2], f11 = q10 * P[1] + q11 * P[3];
  const Lanes c = f00 + f11, s = f10 - f01;
  const Lanes r = (c * c + s * s).sqrt();
  const Lanes cr = c / r, sr = s / r;
  for (int l = 0; l < 4; ++l) {
    // A degenerate triangle (or a non-finite one) takes the one-triangle path and its guards.
    if (!(edge2[l] > 0 && normal2[l] > 0 && r[l] > 0)) {
      frame_[first + l] = current_frame(first + l, x);
      continue;
    }
    for (int i = 0; i < 3; ++i) {
      frame_[first + l](i, 0) = a[i][l] * cr[l] + b[i][l] * sr[l];
      frame_[first + l](i, 1) = b[i][l] * cr[l] - a[i][l] * sr[l];
    }
  }
}

void MembraneCST::update_rotations(const Eigen::VectorXd& x, int first, int count) {
  const int end = first + count;
  for (int block = first; block < end; block += 4) {
    if (block + 4 <= end) {
      update_frames(block, x);
    } else {
      for (int e = block; e < end; ++e) frame_[e] = current_frame(e, x);
    }
  }
}

Eigen::Matrix<double, 6, 1> MembraneCST::corotated_displacement(int e, const Eigen::VectorXd& x) const {
  const Eigen::Matrix<double, 3, 2>& A = frame_[e];
  const Eigen::Vector3d x0 = node(x, F_(e, 0));
  Eigen::Matrix<double, 6, 1> u;
  for (int i = 0; i < 3; ++i)
    u.segment<2>(2 * i) = A.transpose() * (node(x, F_(e, i)) - x0) - p_[e].row(i).transpose();
  return u;
}

double MembraneCST::element_force(int e, const Eigen::VectorXd& x, Vector9d& f) const {
  const Eigen::Matrix<double, 6, 1> u = corotated_displacement(e, x);
  const Eigen::Matrix<double, 6, 1> f2 = K2_[e].lazyProduct(u);
  for (int i = 0; i < 3; ++i) f.segment<3>(3 * i) = frame_[e] * f2.segment<2>(2 * i);
  return 0.5 * u.dot(f2);
}

void MembraneCST::element_tangent(int e, Matrix9d& K) const {
  const Eigen::Matrix<double, 3, 2>& A = frame_[e];
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b)
      K.block<3, 3>(3 * a, 3 * b).noalias() = A * K2_[e].block<2, 2>(2 * a, 2 * b) * A.transpose();
}

void MembraneCST::tangent_product(int e, const Eigen::Matrix<double, 3, 2>& A, const Eigen::VectorXd& v,
                                  Vector9d& out) const {
  Eigen::Matrix<double, 6, 1> v2;
  for (int i = 0; i < 3; ++i) v2.segment<2>(2 * i) = A.transpose() * node(v, F_(e, i));
  const Eigen::Matrix<double, 6, 1> f2 = K2_[e].lazyProduct(v2);
  for (int i = 0; i < 3; ++i) out.segment<3>(3 * i) = A * f2.segment<2>(2 * i);
}

Eigen::Matrix2d MembraneCST::corotated_strain(int e, const Eigen::VectorXd& x) const {
  const Eigen::Matrix<double, 3, 2>& A = frame_[e];
  const Eigen::Vector3d x0 = node(x, F_(e, 0));
  Eigen::Matrix2d Q;
  Q << A.transpose() * (node(x, F_(e, 1)) - x0), A.transpose() * (node(x, F_(e, 2)) - x0);
  const Eigen::Matrix2d G = Q * Pm_inv_[e];
  return 0.5 * (G + G.transpose()) - Eigen::Matrix2d::Identity();
}

}  // namespace liver_sim
