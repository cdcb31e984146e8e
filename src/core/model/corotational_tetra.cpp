#include "liver_sim/model/corotational_tetra.h"


#include <algorithm>
#include <array>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <cmath>
#include <limits>

#include "liver_sim/geometry/node_positions.h"

namespace liver_sim {
namespace {

// Orthonormal frame (columns) of the first edge and the plane of the first two edges.
Eigen::Matrix3d edge_frame(const Eigen::Vector3d& e01, const Eigen::Vector3d& e02) {
  Eigen::Matrix3d frame;
  const Eigen::Vector3d a = e01.normalized();
  const Eigen::Vector3d c = a.cross(e02).normalized();
  frame << a, c.cross(a), c;
  return frame;
}

}  // namespace

namespace {

LaneMatrix lanes_of(const std::array<const Eigen::Matrix3d*, 4>& A) {
  LaneMatrix L;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) L(i, j) = Lanes((*A[0])(i, j), (*A[1])(i, j), (*A[2])(i, j), (*A[3])(i, j));
  return L;
}

Eigen::Matrix3d lane(const LaneMatrix& L, int l) {
  Eigen::Matrix3d A;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) A(i, j) = L(i, j)[l];
  return A;
}

void set_lane(LaneMatrix& L, int l, const Eigen::Matrix3d& A) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) L(i, j)[l] = A(i, j);
}

// A B, A^T B and A B^T.
LaneMatrix product(const LaneMatrix& A, const LaneMatrix& B) {
  LaneMatrix C;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) C(i, j) = A(i, 0) * B(0, j) + A(i, 1) * B(1, j) + A(i, 2) * B(2, j);
  return C;
}

LaneMatrix transpose_product(const LaneMatrix& A, const LaneMatrix& B) {
  LaneMatrix C;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) C(i, j) = A(0, i) * B(0, j) + A(1, i) * B(1, j) + A(2, i) * B(2, j);
  return C;
}

LaneMatrix product_transpose(const LaneMatrix& A, const LaneMatrix& B) {
  LaneMatrix C;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) C(i, j) = A(i, 0) * B(j, 0) + A(i, 1) * B(j, 1) + A(i, 2) * B(j, 2);
  return C;
}

// The rotation matrix of unit quaternions (w, x, y, z), as Eigen's toRotationMatrix.
LaneMatrix lane_rotation(const Lanes& w, const Lanes& x, const Lanes& y, const Lanes& z) {
  const Lanes tx = 2 * x, ty = 2 * y, tz = 2 * z;
  const Lanes twx = tx * w, twy = ty * w, twz = tz * w;
  const Lanes txx = tx * x, txy = ty * x, txz = tz * x;
  const Lanes tyy = ty * y, tyz = tz * y, tzz = tz * z;
  LaneMatrix r;
  r(0, 0) = 1 - (tyy + tzz);
  r(0, 1) = txy - twz;
  r(0, 2) = txz + twy;
  r(1, 0) = txy + twz;
  r(1, 1) = 1 - (txx + tzz);
  r(1, 2) = tyz - twx;
  r(2, 0) = txz - twy;
  r(2, 1) = tyz + twx;
  r(2, 2) = 1 - (txx + tyy);
  return r;
}

// The warm iteration above, lane by lane (same formulas): a scalar step is a chain of dependent
// operations, four independent ones fill the vector units. Two steps in lanes cover the usual
// changes between evaluations; a lane the step does not suit, or that needs more, goes on alone.
LaneMatrix polar_lanes(const LaneMatrix& F, const std::array<Eigen::Quaterniond*, 4>& q) {
  Lanes qw(q[0]->w(), q[1]->w(), q[2]->w(), q[3]->w()), qx(q[0]->x(), q[1]->x(), q[2]->x(), q[3]->x()),
      qy(q[0]->y(), q[1]->y(), q[2]->y(), q[3]->y()), qz(q[0]->z(), q[1]->z(), q[2]->z(), q[3]->z());
  LaneMatrix R;
  std::array<bool, 4> converged{}, alone{};
  for (int step = 0; step < 2; ++step) {
    const LaneMatrix G = transpose_product(lane_rotation(qw, qx, qy, qz), F);
    const Lanes a0 = G(2, 1) - G(1, 2), a1 = G(0, 2) - G(2, 0), a2 = G(1, 0) - G(0, 1);
    const Lanes trace = G(0, 0) + G(1, 1) + G(2, 2);
    const Lanes a00 = trace - G(0, 0), a11 = trace - G(1, 1), a22 = trace - G(2, 2);
    const Lanes a01 = -0.5 * (G(0, 1) + G(1, 0)), a02 = -0.5 * (G(0, 2) + G(2, 0)), a12 = -0.5 * (G(1, 2) + G(2, 1));
    const Lanes c00 = a11 * a22 - a12 * a12, c01 = a02 * a12 - a01 * a22, c02 = a01 * a12 - a02 * a11;
    const Lanes det = a00 * c00 + a01 * c01 + a02 * c02;
    const Lanes c11 = a00 * a22 - a02 * a02, c12 = a01 * a02 - a00 * a12, c22 = a00 * a11 - a01 * a01;
    const Lanes inv_det = 1.0 / det;
    const Lanes wx = (c00 * a0 + c01 * a1 + c02 * a2) * inv_det, wy = (c01 * a0 + c11 * a1 + c12 * a2) * inv_det,
                wz = (c02 * a0 + c12 * a1 + c22 * a2) * inv_det;
    const Lanes w2 = wx * wx + wy * wy + wz * wz;
    const Lanes hx = 0.5 * wx, hy = 0.5 * wy, hz = 0.5 * wz;
    const Lanes nx = qw * hx + qy * hz - qz * hy + qx, ny = qw * hy + qz * hx - qx * hz + qy,
                nz = qw * hz + qx * hy - qy * hx + qz, nw = qw - (qx * hx + qy * hy + qz * hz);
    const Lanes inv_norm = 1.0 / (nx * nx + ny * ny + nz * nz + nw * nw).sqrt();
    qw = nw * inv_norm;
    qx = nx * inv_norm;
    qy = ny * inv_norm;
    qz = nz * inv_norm;
    const LaneMatrix R_step = lane_rotation(qw, qx, qy, qz);
    bool more = false;
    for (int l = 0; l < 4; ++l) {
      if (converged[l] || alone[l]) continue;
      alone[l] = !(a00[l] > 0 && a00[l] * a11[l] > a01[l] * a01[l] && det[l] > 0 && w2[l] < 0.25);
      if (alone[l]) continue;
      *q[l] = Eigen::Quaterniond(qw[l], qx[l], qy[l], qz[l]);
      converged[l] = w2[l] < 1e-10;
      if (converged[l]) set_lane(R, l, lane(R_step, l));
      more = more || !converged[l];
    }
    if (!more) break;
  }
  for (int l = 0; l < 4; ++l)
    if (!converged[l]) set_lane(R, l, polar_rotation(lane(F, l), *q[l]));
  return R;
}

}  // namespace

CorotationalTetra::CorotationalTetra(const Eigen::MatrixX3d& X, const Eigen::MatrixX4i& T,
                                     const ParenchymaOptions& material)
    : T_(T), method_(material.rotation) {
  const int n = static_cast<int>(T.rows());
  Dm_inv_.resize(n);
  rest_frame_T_.resize(n);
  grad_N_.resize(n);
  volume_.resize(n);
  R_.assign(n, Eigen::Matrix3d::Identity());
  q_.assign(n, Eigen::Quaterniond::Identity());
  q_step_ = q_;
  for (int e = 0; e < n; ++e) {
    Eigen::Matrix3d Dm;
    for (int i = 0; i < 3; ++i) Dm.col(i) = (X.row(T(e, i + 1)) - X.row(T(e, 0))).transpose();
    volume_[e] = Dm.determinant() / 6.0;
    Dm_inv_[e] = Dm.inverse();
    rest_frame_T_[e] = edge_frame(Dm.col(0), Dm.col(1)).transpose();
    // Rows of Dm^-1 are the gradients of N1..N3; N0 = 1 - N1 - N2 - N3.
    grad_N_[e].bottomRows<3>() = Dm_inv_[e];
    grad_N_[e].row(0) = -Dm_inv_[e].colwise().sum();
  }
  blocks_.resize(n / 4);
  for (int b = 0; b < n / 4; ++b) {
    const int e = 4 * b;
    blocks_[b].Dm_inv = lanes_of({&Dm_inv_[e], &Dm_inv_[e + 1], &Dm_inv_[e + 2], &Dm_inv_[e + 3]});
    blocks_[b].volume = Lanes(volume_[e], volume_[e + 1], volume_[e + 2], volume_[e + 3]);
  }
  set_material(material);
}

void CorotationalTetra::set_material(const ParenchymaOptions& material) {
  const double E = material.young_modulus, nu = material.poisson_ratio;
  const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu));
  const double mu = E / (2 * (1 + nu));
  lambda_ = lambda;
  mu_ = mu;
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

namespace {

// det F above this (relative to |F|^3): neither inverted nor nearly flat, so the Newton
// iterations below converge; otherwise the SVD decides.
bool well_shaped(const Eigen::Matrix3d& F) { return F.determinant() > 1e-3 * F.squaredNorm() * F.norm(); }

Eigen::Matrix3d polar_rotation_svd(const Eigen::Matrix3d& F) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  const Eigen::Matrix3d& V = svd.matrixV();
  // An inverted element has det F < 0: flip the axis of the smallest singular value so that
  // R stays a proper rotation and the element is pushed back through (Irving et al. 2004).
  if ((U * V.transpose()).determinant() < 0) U.col(2) = -U.col(2);
  return U * V.transpose();
}

}  // namespace

Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& F) {
  // Scaled Newton iteration for the polar factor, X <- (g X + X^-T / g) / 2 with Frobenius-norm
  // scaling (Higham 1986), to round-off: the Jacobian products of the Newton-Krylov solver
  // difference the forces at 1e-8 steps. A non-finite F gives a non-finite R, as the state's
  // checks expect: Eigen's SVD of it reads values it never set (valgrind), a finite garbage R.
  if (!F.allFinite()) return Eigen::Matrix3d::Constant(std::numeric_limits<double>::quiet_NaN());
  if (!well_shaped(F)) return polar_rotation_svd(F);
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

Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& F, Eigen::Quaterniond& q) {
  // Newton on the rotation itself, from q: R = R(q) exp(w) with w from the skew part of
  // G = R^T F, (tr(S) I - S) w = axial(G - G^T), S = sym(G). It converges quadratically from a
  // nearby rotation (an element's rotation changes little between two evaluations): two
  // iterations where the scaled iteration from F needs five or more. The unit quaternion stays a
  // rotation to round-off however often it is updated. The fixed point with A = tr(S) I - S
  // positive definite is the SVD's answer also for an inverted element, so no shape test is
  // needed here.
  for (int k = 0; k < 6; ++k) {
    const Eigen::Matrix3d G = q.toRotationMatrix().transpose() * F;
    const Eigen::Vector3d a(G(2, 1) - G(1, 2), G(0, 2) - G(2, 0), G(1, 0) - G(0, 1));
    const double trace = G.trace();
    const double a00 = trace - G(0, 0), a11 = trace - G(1, 1), a22 = trace - G(2, 2);
    const double a01 = -0.5 * (G(0, 1) + G(1, 0)), a02 = -0.5 * (G(0, 2) + G(2, 0)), a12 = -0.5 * (G(1, 2) + G(2, 1));
    // A is positive definite at the polar factor (its eigenvalues are sums of two singular
    // values) and near it; not at the other rotations that make G symmetric (a half turn away).
    // Otherwise, or too far (or not finite), start from F.
    const double c00 = a11 * a22 - a12 * a12, c01 = a02 * a12 - a01 * a22, c02 = a01 * a12 - a02 * a11;
    const double det = a00 * c00 + a01 * c01 + a02 * c02;
    if (!(a00 > 0 && a00 * a11 > a01 * a01 && det > 0)) break;
    // w = A^-1 a by cofactors. The quadratic terms of the skew part of exp(-w) G cancel (for
    // symmetric S, a x w + S w x w = O(|w|^3)): one step leaves an error of ~|w|^3 / 3, so one
    // suffices for the changes between evaluations (|w| < 1e-5).
    const double c11 = a00 * a22 - a02 * a02, c12 = a01 * a02 - a00 * a12, c22 = a00 * a11 - a01 * a01;
    const Eigen::Vector3d w = Eigen::Vector3d(c00 * a[0] + c01 * a[1] + c02 * a[2], c01 * a[0] + c11 * a[1] + c12 * a[2],
                                              c02 * a[0] + c12 * a[1] + c22 * a[2]) *
                              (1.0 / det);
    const double w2 = w.squaredNorm();
    if (!(w2 < 0.25)) break;
    // q (1, w/2), back to unit length: the rotation exp(w) with an angle error of |w|^3 / 12.
    const Eigen::Vector3d h = 0.5 * w;
    const Eigen::Vector3d v = q.vec();
    const Eigen::Vector4d next(q.w() * h.x() + v.y() * h.z() - v.z() * h.y() + v.x(),
                               q.w() * h.y() + v.z() * h.x() - v.x() * h.z() + v.y(),
                               q.w() * h.z() + v.x() * h.y() - v.y() * h.x() + v.z(), q.w() - v.dot(h));
    q.coeffs() = next * (1.0 / next.norm());
    if (w2 < 1e-10) return q.toRotationMatrix();  // converged to ~|w|^3 < 1e-15
  }
  const Eigen::Matrix3d R = polar_rotation(F);
  q = Eigen::Quaterniond(R);
  return R;
}

void polar_rotations(const std::array<Eigen::Matrix3d, 4>& F, const std::array<Eigen::Quaterniond*, 4>& q,
                     std::array<Eigen::Matrix3d, 4>& R) {
  const LaneMatrix rotations = polar_lanes(lanes_of({&F[0], &F[1], &F[2], &F[3]}), q);
  for (int l = 0; l < 4; ++l) R[l] = lane(rotations, l);
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


void CorotationalTetra::update_rotations(const Eigen::VectorXd& x) {
  for (int e = 0; e < size(); ++e) update_rotation(e, x, deformation_gradient(e, x));
}

void CorotationalTetra::reset_rotations() {
  std::fill(R_.begin(), R_.end(), Eigen::Matrix3d::Identity());
  std::fill(q_.begin(), q_.end(), Eigen::Quaterniond::Identity());
  std::fill(q_step_.begin(), q_step_.end(), Eigen::Quaterniond::Identity());
}

void CorotationalTetra::predict_rotations(bool continued) {
  if (method_ != RotationMethod::Polar) return;
  for (int e = 0; e < size(); ++e) {
    const Eigen::Quaterniond q = q_[e];
    if (continued) q_[e] = (q * q_step_[e].conjugate() * q).normalized();
    q_step_[e] = q;
  }
}

void CorotationalTetra::update_rotation(int e, const Eigen::VectorXd& x, const Eigen::Matrix3d& F) {
  // Polar: warm-started from the element's last rotation.
  R_[e] = method_ == RotationMethod::Geometric ? rotation_geometric(e, x) : polar_rotation(F, q_[e]);
}

Eigen::Matrix3d CorotationalTetra::rotated_stress(const Eigen::Matrix3d& G) const {
  // K0 u = V sigma g per node (g: shape-function gradient), with the linear strain sym(G) of the
  // displacement gradient G in the element's frame: 50 flops instead of the 12x12 product
  // and its 1 kB of K0 read from memory.
  const Eigen::Matrix3d strain = 0.5 * (G + G.transpose());
  Eigen::Matrix3d stress = 2 * mu_ * strain;
  stress.diagonal().array() += lambda_ * strain.trace();
  return stress;
}

void CorotationalTetra::nodal_forces(int e, const Eigen::Matrix3d& P, Vector12d& f) const {
  // f_a = V P g_a; the gradients sum to zero, so node 0 takes minus the others.
  const Eigen::Matrix3d fs = volume_[e] * P * Dm_inv_[e].transpose();
  f.segment<3>(3) = fs.col(0);
  f.segment<3>(6) = fs.col(1);
  f.segment<3>(9) = fs.col(2);
  f.head<3>() = -(fs.col(0) + fs.col(1) + fs.col(2));
}

double CorotationalTetra::element_force(int e, const Eigen::VectorXd& x, Vector12d& f) {
  const Eigen::Matrix3d F = deformation_gradient(e, x);
  update_rotation(e, x, F);
  const Eigen::Matrix3d& R = R_[e];
  Eigen::Matrix3d G = R.transpose() * F;
  G.diagonal().array() -= 1.0;  // R^T F - I: the displacement gradient in the element's frame
  const Eigen::Matrix3d stress = rotated_stress(G);
  nodal_forces(e, R * stress, f);
  return 0.5 * volume_[e] * (stress.cwiseProduct(G)).sum();
}

LaneMatrix CorotationalTetra::lane_gradient(int first, const Eigen::VectorXd& x) const {
  LaneMatrix Ds;
  for (int l = 0; l < 4; ++l) {
    const Eigen::Vector3d x0 = node(x, T_(first + l, 0));
    for (int j = 0; j < 3; ++j) {
      const Eigen::Vector3d edge = node(x, T_(first + l, j + 1)) - x0;
      for (int i = 0; i < 3; ++i) Ds(i, j)[l] = edge[i];
    }
  }
  return product(Ds, blocks_[first / 4].Dm_inv);
}

Lanes CorotationalTetra::lane_forces(int first, const LaneMatrix& R, const LaneMatrix& G, Vector12d* f) const {
  // As element_force: the stress of the gradient G in the elements' frames, then V R sigma g_a.
  const Block& block = blocks_[first / 4];
  const Lanes trace = G(0, 0) + G(1, 1) + G(2, 2);
  LaneMatrix stress;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) stress(i, j) = mu_ * (G(i, j) + G(j, i));
  for (int i = 0; i < 3; ++i) stress(i, i) += lambda_ * trace;
  const LaneMatrix fs = product_transpose(product(R, stress), block.Dm_inv);
  for (int l = 0; l < 4; ++l) {
    for (int a = 1; a < 4; ++a)
      for (int i = 0; i < 3; ++i) f[l][3 * a + i] = block.volume[l] * fs(i, a - 1)[l];
    f[l].head<3>() = -(f[l].segment<3>(3) + f[l].segment<3>(6) + f[l].segment<3>(9));
  }
  Lanes work = Lanes::Zero();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) work += stress(i, j) * G(i, j);
  return 0.5 * block.volume * work;
}

double CorotationalTetra::element_forces(int first, int count, const Eigen::VectorXd& x, Vector12d* f) {
  if (count < 4 || first % 4 != 0 || method_ != RotationMethod::Polar) {
    double energy = 0;
    for (int i = 0; i < count; ++i) energy += element_force(first + i, x, f[i]);
    return energy;
  }
  const LaneMatrix F = lane_gradient(first, x);
  const LaneMatrix R = polar_lanes(F, {&q_[first], &q_[first + 1], &q_[first + 2], &q_[first + 3]});
  for (int l = 0; l < 4; ++l) R_[first + l] = lane(R, l);
  LaneMatrix G = transpose_product(R, F);
  for (int i = 0; i < 3; ++i) G(i, i) -= 1.0;  // R^T F - I: the displacement gradient in the elements' frames
  return lane_forces(first, R, G, f).sum();
}

void CorotationalTetra::tangent_products(int first, int count, const std::vector<Eigen::Matrix3d>& R,
                                         const Eigen::VectorXd& v, Vector12d* out) const {
  if (count < 4 || first % 4 != 0) {
    for (int i = 0; i < count; ++i) tangent_product(first + i, R[first + i], v, out[i]);
    return;
  }
  const LaneMatrix rotation = lanes_of({&R[first], &R[first + 1], &R[first + 2], &R[first + 3]});
  lane_forces(first, rotation, transpose_product(rotation, lane_gradient(first, v)), out);
}

void CorotationalTetra::tangent_product(int e, const Eigen::Matrix3d& R, const Eigen::VectorXd& v, Vector12d& out) const {
  // R K0 R^T v: the same kernel on the velocity gradient rotated into the element's frame.
  const Eigen::Matrix3d G = R.transpose() * deformation_gradient(e, v);
  nodal_forces(e, R * rotated_stress(G), out);
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
