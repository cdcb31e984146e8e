#include "liver_sim/registration/target_uncertainty.h"

#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "liver_sim/geometry/node_positions.h"
#include "liver_sim/registration/registration.h"

namespace liver_sim {

std::vector<EmbeddedPoint> embed_points(const Eigen::MatrixX4i& T, const Eigen::VectorXd& x,
                                        const std::vector<Eigen::Vector3d>& points) {
  std::vector<Eigen::Matrix3d> inverse(T.rows());
  for (int e = 0; e < T.rows(); ++e) {
    Eigen::Matrix3d edges;
    for (int k = 1; k < 4; ++k) edges.col(k - 1) = node(x, T(e, k)) - node(x, T(e, 0));
    inverse[e] = edges.inverse();
  }
  std::vector<EmbeddedPoint> embedded(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    double best_min = -std::numeric_limits<double>::infinity();
    for (int e = 0; e < T.rows(); ++e) {
      const Eigen::Vector3d w = inverse[e] * (points[i] - node(x, T(e, 0)));
      const Eigen::Vector4d b(1 - w.sum(), w.x(), w.y(), w.z());
      if (b.minCoeff() > best_min) best_min = b.minCoeff(), embedded[i].tet = e, embedded[i].barycentric = b;
    }
  }
  return embedded;
}

Ellipsoid ellipsoid_95(const Eigen::Matrix3d& covariance) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(covariance);
  Ellipsoid e;
  e.semi_axes = (kChiSquare3At95 * eigen.eigenvalues().cwiseMax(0.0)).cwiseSqrt();
  e.axes = eigen.eigenvectors();
  if (e.axes.determinant() < 0) e.axes.col(2) *= -1;
  return e;
}

TargetUncertainty::TargetUncertainty(LiverModel& model, const UncertaintyOptions& options)
    : model_(model), options_(options) {
  RegistrationOptions checked;
  checked.uncertainty = options;
  const std::string error = validate(checked);
  if (!error.empty()) throw std::invalid_argument(error);
  MechanicalModel& m = model.mechanics();
  std::vector<Eigen::Vector3d> points;
  for (const TrackedTarget& t : tracked_targets(model)) points.push_back(t.position);
  embedding_ = embed_points(m.mesh().T, model.positions(), points);

  patches_ = make_surface_patches(m, options.patch_spacing);
  std::vector<Eigen::Triplet<double>> entries;
  for (size_t p = 0; p < patches_.nodes.size(); ++p)
    for (size_t k = 0; k < patches_.nodes[p].size(); ++k)
      for (int a = 0; a < 3; ++a) entries.emplace_back(3 * patches_.nodes[p][k] + a, 3 * p + a, patches_.weights[p][k]);
  patch_forces_.resize(m.rest_positions().size(), 3 * patches_.nodes.size());
  patch_forces_.setFromTriplets(entries.begin(), entries.end());
}

Eigen::Vector3d TargetUncertainty::position(int target, const Eigen::VectorXd& x) const {
  return interpolate(model_.mesh().T, x, embedding_[target]);
}

std::vector<TargetUncertainty::Covariance> TargetUncertainty::covariances(StateCompliance& compliance,
                                                                          const std::vector<SurfaceTarget>& springs) {
  const Eigen::VectorXd& x = compliance.state();
  const int n = static_cast<int>(x.size()), targets = num_targets();
  // Z = A^-1 J^T: three columns per target (zero at the supports).
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(n, 3 * targets), Z;
  const Eigen::MatrixX4i& T = model_.mesh().T;
  for (int i = 0; i < targets; ++i)
    for (int k = 0; k < 4; ++k)
      for (int a = 0; a < 3; ++a) B(3 * T(embedding_[i].tet, k) + a, 3 * i + a) += embedding_[i].barycentric[k];
  compliance.solve(B, Z);
  const MechanicalModel& m = model_.mechanics();
  const Eigen::VectorXd& f_int = compliance.equilibrium_internal_forces();

  // The springs: the net force of each patch they pull on (its typical size scales the unknown
  // forces), and their RMS length (the sensor's noise after the voxel grid's averaging), both
  // where a full solve would take the state. The pull is taken where the model would be
  // without the hidden loads the registration found (- A^-1 f, linearised; the springs are
  // linear in x): the loads carry part of what the cloud shows of the surgery's forces, not
  // less of it.
  const Eigen::MatrixX3i& F = m.boundary();
  const Eigen::VectorXd& settled = compliance.equilibrium();
  Eigen::VectorXd unloaded = settled;
  if (model_.surface_loads().size() == x.size()) {
    Eigen::MatrixXd moved;
    compliance.solve(model_.surface_loads(), moved);
    unloaded -= moved.col(0);
  }
  const std::vector<Eigen::Vector3d> pull = patch_spring_forces(patches_, F, springs, unloaded);
  std::vector<char> pulled(pull.size(), 0);
  double length_squared = 0;
  for (const SurfaceTarget& s : springs) {
    pulled[patches_.triangle_patch[s.triangle]] = 1;
    length_squared += s.stretch(settled, F).squaredNorm();
  }
  double sum = 0;
  int count = 0;
  for (size_t p = 0; p < pull.size(); ++p)
    if (pulled[p]) sum += pull[p].squaredNorm(), ++count;
  typical_force_ = count > 0 ? std::sqrt(sum / count) : 0.0;
  const double patch_sd = options_.force_ratio * typical_force_;
  const double noise_sd = springs.empty() ? 0.0 : std::sqrt(length_squared / springs.size());

  std::vector<Covariance> covariance(targets);
  // Unknown patch forces: G = Phi^T Z (target displacements per unit patch force).
  const Eigen::MatrixXd G = patch_forces_.transpose() * Z;
  // Stiffness: the equilibrium's shift per unit log-stiffness, -A^-1 f_int, f_int the internal
  // forces there (the supports' rows of Z are zero: their reactions do not count).
  const Eigen::VectorXd stiffness_shift = Z.transpose() * f_int;
  // Noise: a spring's point moved by u along its normal moves the state by A^-1 k w n u.
  Eigen::MatrixXd noise = Eigen::MatrixXd::Zero(springs.size(), 3 * targets);
  for (size_t s = 0; s < springs.size(); ++s) {
    const SurfaceTarget& t = springs[s];
    if (t.normal.isZero(0.0)) continue;  // point-to-point springs: left out (no normal to move along)
    for (int j = 0; j < 3; ++j)
      noise.row(s) += t.stiffness * t.weights[j] * (t.normal.transpose() * Z.middleRows(3 * F(t.triangle, j), 3));
  }
  for (int i = 0; i < targets; ++i) {
    const auto g = G.middleCols(3 * i, 3);
    const Eigen::Vector3d v = stiffness_shift.segment<3>(3 * i);
    const auto u = noise.middleCols(3 * i, 3);
    Covariance& c = covariance[i];
    c.forces = patch_sd * patch_sd * g.transpose() * g;
    c.stiffness = options_.stiffness_log_sd * options_.stiffness_log_sd * v * v.transpose();
    c.noise = noise_sd * noise_sd * u.transpose() * u;
    c.total = c.forces + c.stiffness + c.noise;
  }
  return covariance;
}

}  // namespace liver_sim
