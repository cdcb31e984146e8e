// The registration's estimates from the springs' pull on the surface patches: candidate
// supports, the tissue's stiffness, the hidden loads (registration.h).
#include <Eigen/SparseCore>

#include <algorithm>
#include <cmath>

#include "liver_sim/registration/registration.h"

namespace liver_sim {
namespace {

// Huber weights over the patches' pulls, of width twice the median of the nonzero ones (zero
// pulls weigh nothing): an instrument pressing where the camera sees does not decide a fit.
std::vector<double> patch_weights(const std::vector<Eigen::Vector3d>& pull) {
  std::vector<double> sizes, w(pull.size(), 0.0);
  for (const Eigen::Vector3d& r : pull)
    if (r.squaredNorm() > 0) sizes.push_back(r.norm());
  if (sizes.empty()) return w;
  std::nth_element(sizes.begin(), sizes.begin() + sizes.size() / 2, sizes.end());
  const double width = 2 * sizes[sizes.size() / 2];
  for (size_t p = 0; p < pull.size(); ++p)
    if (pull[p].squaredNorm() > 0) w[p] = pull[p].norm() <= width ? 1.0 : width / pull[p].norm();
  return w;
}

}  // namespace

double SurfaceRegistration::systematic_pull(const std::vector<SurfaceTarget>& springs, const Eigen::VectorXd& x) const {
  double sum = 0;
  for (const Eigen::Vector3d& f : patch_spring_forces(patches_, model_.boundary(), springs, x)) sum += f.squaredNorm();
  return sum;
}

int SurfaceRegistration::estimate_supports(StateCompliance& compliance, const std::vector<SurfaceTarget>& springs) {
  std::vector<int> tried;
  for (size_t c = 0; c < supports_.size(); ++c)
    if (!held_[c]) tried.push_back(static_cast<int>(c));
  if (tried.empty()) return -1;
  const Eigen::VectorXd& x = compliance.equilibrium();
  const double before = systematic_pull(springs, x);
  if (!(before > 0)) return -1;
  // Phi: per candidate, unit forces in x, y, z spread over its nodes; U = A^-1 Phi.
  Eigen::MatrixXd Phi = Eigen::MatrixXd::Zero(x.size(), 3 * tried.size()), U;
  for (size_t k = 0; k < tried.size(); ++k) {
    const Candidate& c = supports_[tried[k]];
    for (size_t i = 0; i < c.nodes.size(); ++i)
      for (int a = 0; a < 3; ++a) Phi(3 * c.nodes[i] + a, 3 * k + a) = c.weights[i];
  }
  compliance.solve(Phi, U);
  const Eigen::VectorXd& X = model_.mechanics().rest_positions();
  int best = -1;
  for (size_t k = 0; k < tried.size(); ++k) {
    const auto phi = Phi.middleCols(3 * k, 3), u = U.middleCols(3 * k, 3);
    const Eigen::Matrix3d M = phi.transpose() * u;
    const Eigen::Vector3d R = M.ldlt().solve(phi.transpose() * (X - x));
    const double gain = 1.0 - systematic_pull(springs, x + u * R) / before;
    gains_[tried[k]] = gain;
    if (gain >= options_.support_gain && (best < 0 || gain > gains_[best])) best = tried[k];
  }
  if (best >= 0) {
    held_[best] = true;
    apply_springs();
  }
  return best;
}

double SurfaceRegistration::estimate_tissue_stiffness(StateCompliance& compliance,
                                                      const std::vector<SurfaceTarget>& springs) {
  const double scale = model_.stiffness_scale();
  if (springs.empty() || !options_.estimates_tissue_stiffness()) return scale;
  const Eigen::VectorXd& x = compliance.equilibrium();
  const Eigen::MatrixX3i& F = model_.boundary();
  const std::vector<Eigen::Vector3d> pull = patch_spring_forces(patches_, F, springs, x);
  Eigen::MatrixXd u;
  compliance.solve(-compliance.equilibrium_internal_forces(), u);  // d x / d ln s
  const std::vector<Eigen::Vector3d> moved = patch_spring_forces(patches_, F, springs, x + u.col(0));
  const std::vector<double> w = patch_weights(pull);
  double along = 0, squared = 0;
  for (size_t p = 0; p < pull.size(); ++p) {
    const Eigen::Vector3d J = moved[p] - pull[p];  // the springs are linear in x
    along += w[p] * J.dot(pull[p]);
    squared += w[p] * J.squaredNorm();
  }
  if (!(squared > 0)) return scale;
  const double step = std::clamp(-along / squared, -std::log(2.0), std::log(2.0));
  const double estimate =
      std::clamp(scale * std::exp(step), options_.min_tissue_stiffness_factor, options_.max_tissue_stiffness_factor);
  model_.set_stiffness_scale(estimate);
  return estimate;
}

double SurfaceRegistration::estimate_hidden_loads(StateCompliance& compliance,
                                                  const std::vector<SurfaceTarget>& springs) {
  return apply_hidden_loads(hidden_load_fit(compliance, springs, hidden_loads_));
}

SurfaceRegistration::HiddenLoadFit SurfaceRegistration::hidden_load_fit(StateCompliance& compliance,
                                                                        const std::vector<SurfaceTarget>& springs,
                                                                        const std::vector<Eigen::Vector3d>& loads) const {
  HiddenLoadFit fit;
  if (!options_.estimate_hidden_loads || springs.empty()) return fit;
  fit.loads = loads;
  const Eigen::VectorXd& x = compliance.equilibrium();
  const Eigen::MatrixX3i& F = model_.boundary();
  std::vector<char> touched(patches_.centres.size(), 0);
  for (const SurfaceTarget& t : springs) touched[patches_.triangle_patch[t.triangle]] = 1;
  for (size_t p = 0; p < patches_.centres.size(); ++p)
    if (!touched[p] && !patches_.nodes[p].empty()) fit.patches.push_back(static_cast<int>(p));
  fit.hidden = static_cast<int>(fit.patches.size());
  for (size_t p = 0; p < patches_.centres.size(); ++p)
    if (touched[p] && !loads[p].isZero(0.0)) fit.patches.push_back(static_cast<int>(p));
  const std::vector<Eigen::Vector3d> pull = patch_spring_forces(patches_, F, springs, x);
  const std::vector<double> w = patch_weights(pull);
  const int n = 3 * static_cast<int>(fit.patches.size());
  std::vector<Eigen::Triplet<double>> entries;
  for (size_t k = 0; k < fit.patches.size(); ++k) {
    const int p = fit.patches[k];
    for (size_t i = 0; i < patches_.nodes[p].size(); ++i)
      for (int a = 0; a < 3; ++a) entries.emplace_back(3 * patches_.nodes[p][i] + a, 3 * k + a, patches_.weights[p][i]);
  }
  Eigen::SparseMatrix<double> Phi(x.size(), n);
  Phi.setFromTriplets(entries.begin(), entries.end());
  // J = S A^-1 Phi, S the touched patches' pull per unit state change (the springs are linear
  // in x), solved as (A^-1 S^T)^T Phi (A is symmetric): three columns per touched patch rather
  // than per loaded one, which are the more at a partial view.
  std::vector<int> column(pull.size(), -1);
  int m = 0;
  for (size_t p = 0; p < pull.size(); ++p)
    if (touched[p]) column[p] = 3 * m++;
  Eigen::MatrixXd St = Eigen::MatrixXd::Zero(x.size(), 3 * m), V;
  for (const SurfaceTarget& t : springs) {
    const Eigen::Matrix3d along = t.projector();
    for (int j = 0; j < 3; ++j)
      St.block<3, 3>(3 * F(t.triangle, j), column[patches_.triangle_patch[t.triangle]]) -= t.stiffness * t.weights[j] * along;
  }
  fit.J = Eigen::MatrixXd::Zero(3 * pull.size(), n);
  if (n > 0 && m > 0) {
    compliance.solve(St, V);
    const Eigen::MatrixXd VtPhi = V.transpose() * Phi;
    for (size_t p = 0; p < pull.size(); ++p)
      if (touched[p]) fit.J.middleRows<3>(3 * p) = std::sqrt(w[p]) * VtPhi.middleRows<3>(column[p]);
  }
  fit.r.resize(3 * pull.size());
  for (size_t p = 0; p < pull.size(); ++p) fit.r.segment<3>(3 * p) = std::sqrt(w[p]) * pull[p];
  return fit;
}

double SurfaceRegistration::apply_hidden_loads(const HiddenLoadFit& fit) {
  if (fit.patches.empty() || fit.loads != hidden_loads_) return hidden_load_total();
  // The patches now in view drop their loads, and the pull the fit sees changes by as much.
  Eigen::VectorXd r = fit.r;
  for (size_t k = fit.hidden; k < fit.patches.size(); ++k) {
    r -= fit.J.middleCols(3 * k, 3) * hidden_loads_[fit.patches[k]];
    hidden_loads_[fit.patches[k]].setZero();
  }
  const int n = 3 * fit.hidden;
  if (n > 0) {
    const auto J = fit.J.leftCols(n);
    Eigen::VectorXd g(n);
    for (int k = 0; k < fit.hidden; ++k) g.segment<3>(3 * k) = hidden_loads_[fit.patches[k]];
    Eigen::MatrixXd N = J.transpose() * J;
    const double lambda = options_.hidden_load_damping * N.trace() / n;
    if (lambda > 0) {
      N.diagonal().array() += lambda;
      const Eigen::VectorXd step = N.ldlt().solve(-J.transpose() * r - lambda * g);
      if (step.allFinite())
        for (int k = 0; k < fit.hidden; ++k) hidden_loads_[fit.patches[k]] += step.segment<3>(3 * k);
    }
  }
  set_model_loads();
  return hidden_load_total();
}

void SurfaceRegistration::note_step(const StepResult& step) {
  if (step.status != StepResult::Status::Diverged) stepped_loads_ = hidden_loads_;
}

void SurfaceRegistration::set_model_loads() {
  Eigen::VectorXd loads = shape_loads_.size() ? shape_loads_ : Eigen::VectorXd::Zero(model_.positions().size());
  for (size_t p = 0; p < patches_.centres.size(); ++p)
    for (size_t i = 0; i < patches_.nodes[p].size(); ++i)
      loads.segment<3>(3 * patches_.nodes[p][i]) += patches_.weights[p][i] * hidden_loads_[p];
  model_.set_surface_loads(std::move(loads));
}

double SurfaceRegistration::hidden_load_total() const {
  double total = 0;
  for (const Eigen::Vector3d& g : hidden_loads_) total += g.norm();
  return total;
}

}  // namespace liver_sim
