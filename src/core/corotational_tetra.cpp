#include "liver_sim/corotational_tetra.h"


#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <cmath>

namespace liver_sim {
namespace {

Eigen::Vector3d node(const Eigen::VectorXd& x, int i) { return x.segment<3>(3 * i); }

// Orthonormal frame (columns) of the first edge and the plane of the first two edges.
Eigen::Matrix3d edge_frame(const Eigen::Vector3d& e01, const Eigen::Vector3d& e02) {
  Eigen::Matrix3d frame;
  const Eigen::Vector3d a = e01.normalized();
  const Eigen::Vector3d c = a.cross(e02).normalized();
  frame << a, c.cross(a), c;
  return frame;
}

}  // namespace

CorotationalTetra::CorotationalTetra(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T,
                                     const ParenchymaOptions& material)
    : T_(T), method_(material.rotation) {
  const int n = static_cast<int>(T.rows());
  X_.resize(n);
  Dm_inv_.resize(n);
  rest_frame_T_.resize(n);
  grad_N_.resize(n);
  volume_.resize(n);
  R_.assign(n, Eigen::Matrix3d::Identity());
  for (int e = 0; e < n; ++e) {
    Eigen::Matrix3d Dm;
    for (int i = 0; i < 4; ++i) X_[e].segment<3>(3 * i) = X.row(T(e, i)).transpose();
    for (int i = 0; i < 3; ++i) Dm.col(i) = X_[e].segment<3>(3 * (i + 1)) - X_[e].head<3>();
    volume_[e] = Dm.determinant() / 6.0;
    Dm_inv_[e] = Dm.inverse();
    rest_frame_T_[e] = edge_frame(Dm.col(0), Dm.col(1)).transpose();
    // Rows of Dm^-1 are the gradients of N1..N3; N0 = 1 - N1 - N2 - N3.
    grad_N_[e].bottomRows<3>() = Dm_inv_[e];
    grad_N_[e].row(0) = -Dm_inv_[e].colwise().sum();
  }
  set_material(material);
}

void CorotationalTetra::set_material(const ParenchymaOptions& material) {
  const double E = material.young_modulus, nu = material.poisson_ratio;
  const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu));
  const double mu = E / (2 * (1 + nu));
  K0_.resize(volume_.size());
  for (size_t e = 0; e < volume_.size(); ++e) {
    // K_ab = V (lambda g_a g_b^T + mu g_b g_a^T + mu (g_a . g_b) I): isotropic linear elasticity.
    for (int a = 0; a < 4; ++a) {
      const Eigen::Vector3d ga = grad_N_[e].row(a).transpose();
      for (int b = 0; b < 4; ++b) {
        const Eigen::Vector3d gb = grad_N_[e].row(b).transpose();
        K0_[e].block<3, 3>(3 * a, 3 * b) =
            volume_[e] * (lambda * ga * gb.transpose() + mu * gb * ga.transpose() +
                          mu * ga.dot(gb) * Eigen::Matrix3d::Identity());
      }
    }
  }
}

Eigen::Matrix3d CorotationalTetra::deformation_gradient(int e, const Eigen::VectorXd& x) const {
  Eigen::Matrix3d Ds;
  const Eigen::Vector3d x0 = node(x, T_(e, 0));
  for (int i = 0; i < 3; ++i) Ds.col(i) = node(x, T_(e, i + 1)) - x0;
  return Ds * Dm_inv_[e];
}

Eigen::Matrix3d CorotationalTetra::rotation_geometric(int e, const Eigen::VectorXd& x) const {
  const Eigen::Vector3d x0 = node(x, T_(e, 0));
  return edge_frame(node(x, T_(e, 1)) - x0, node(x, T_(e, 2)) - x0) * rest_frame_T_[e];
}

Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& F) {
  // Fast path (elements not inverted or flattened): scaled Newton iteration for the polar
  // factor, X <- (g X + X^-T / g) / 2 with Frobenius-norm scaling (Higham 1986), to round-off:
  // the Jacobian products of the Newton-Krylov solver difference the forces at 1e-8 steps.
  if (F.determinant() > 1e-3 * F.squaredNorm() * F.norm()) {
    Eigen::Matrix3d X = F;
    for (int k = 0; k < 20; ++k) {
      const Eigen::Matrix3d X_inv_T = X.inverse().transpose();
      const double g = std::sqrt(X_inv_T.norm() / X.norm());
      const Eigen::Matrix3d next = 0.5 * (g * X + X_inv_T / g);
      const double change = (next - X).lpNorm<Eigen::Infinity>();
      X = next;
      if (change < 1e-14) break;
    }
    return X;
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  const Eigen::Matrix3d& V = svd.matrixV();
  // An inverted element has det F < 0: flip the axis of the smallest singular value so that
  // R stays a proper rotation and the element is pushed back through (Irving et al. 2004).
  if ((U * V.transpose()).determinant() < 0) U.col(2) = -U.col(2);
  return U * V.transpose();
}

Eigen::Matrix3d cross_matrix(const Eigen::Vector3d& w) {
  Eigen::Matrix3d W;
  W << 0, -w.z(), w.y(), w.z(), 0, -w.x(), -w.y(), w.x(), 0;
  return W;
}

Eigen::Matrix<double, 3, 12> polar_rotation_derivative(const Eigen::Matrix3d& R, const Eigen::Matrix3d& F,
                                                      const Eigen::Matrix3d& Dm_inv) {
  // F = R S: the skew part of R^T dF is (tr(S) I - S) w for the material rotation increment w
  // (dR = R [w]x), and dF = sum_k dx_k b_k^T, so w = (tr(S) I - S)^-1 sum_k b_k x (R^T dx_k).
  const Eigen::Matrix3d RtF = R.transpose() * F;
  const Eigen::Matrix3d S = 0.5 * (RtF + RtF.transpose());
  const Eigen::Matrix3d RA = R * (S.trace() * Eigen::Matrix3d::Identity() - S).inverse();
  Eigen::Matrix<double, 3, 12> G;
  for (int k = 0; k < 4; ++k) {
    // Shape-function gradients: rows of Dm_inv for nodes 1-3, minus their sum for node 0.
    const Eigen::Vector3d b = k == 0 ? Eigen::Vector3d(-Dm_inv.colwise().sum().transpose())
                                     : Eigen::Vector3d(Dm_inv.row(k - 1).transpose());
    G.block<3, 3>(0, 3 * k) = RA * cross_matrix(b) * R.transpose();
  }
  return G;
}

Eigen::Matrix3d CorotationalTetra::rotation_polar(int e, const Eigen::VectorXd& x) const {
  return polar_rotation(deformation_gradient(e, x));
}

void CorotationalTetra::update_rotations(const Eigen::VectorXd& x) {
  const int n = size();
  // Independent per element: split over the cores (OpenMP).
  if (method_ == RotationMethod::Geometric) {
#pragma omp parallel for schedule(static)
    for (int e = 0; e < n; ++e) R_[e] = rotation_geometric(e, x);
  } else {
#pragma omp parallel for schedule(static)
    for (int e = 0; e < n; ++e) R_[e] = rotation_polar(e, x);
  }
}

Vector12d CorotationalTetra::corotated_displacement(int e, const Eigen::VectorXd& x) const {
  const Eigen::Matrix3d& R = R_[e];
  // Displacements relative to node 0 (K0 ignores translations): keeps rounding at the scale of
  // the element, not of the absolute coordinates.
  const Eigen::Vector3d x0 = node(x, T_(e, 0));
  Vector12d u;
  u.head<3>().setZero();
  for (int i = 1; i < 4; ++i)
    u.segment<3>(3 * i) = R.transpose() * (node(x, T_(e, i)) - x0) -
                          (X_[e].segment<3>(3 * i) - X_[e].head<3>());
  return u;
}

double CorotationalTetra::element_force(int e, const Eigen::VectorXd& x, Vector12d& f) const {
  // lazyProduct: an unrolled fixed-size product, not a call into the general matrix-vector kernel.
  const Vector12d u = corotated_displacement(e, x);
  const Vector12d f_local = K0_[e].lazyProduct(u);
  for (int i = 0; i < 4; ++i) f.segment<3>(3 * i) = R_[e] * f_local.segment<3>(3 * i);
  return 0.5 * u.dot(f_local);
}

void CorotationalTetra::element_tangent(int e, Matrix12d& K) const {
  const Eigen::Matrix3d& R = R_[e];
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b)
      K.block<3, 3>(3 * a, 3 * b).noalias() = R * K0_[e].block<3, 3>(3 * a, 3 * b) * R.transpose();
}

Eigen::Matrix3d CorotationalTetra::corotated_strain(int e, const Eigen::VectorXd& x) const {
  const Eigen::Matrix3d G = R_[e].transpose() * deformation_gradient(e, x);
  return 0.5 * (G + G.transpose()) - Eigen::Matrix3d::Identity();
}

}  // namespace liver_sim
