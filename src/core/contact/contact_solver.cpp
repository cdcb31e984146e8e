#include "liver_sim/contact/contact_solver.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>

namespace liver_sim {
namespace {

// A contact's diagonal block of W and its factors, made once per solve (each sweep solves with
// them again: factorised anew every sweep, they took a fifth of the contact solve's time in the
// cube probe's frames).
struct LocalBlock {
  Eigen::Matrix3d Wcc;
  Eigen::LDLT<Eigen::Matrix3d> all;          // the three rows
  Eigen::LDLT<Eigen::Matrix2d> tangential;   // the two slips (a sliding unilateral contact)
};

// The contact's forces that zero its own rows with the others held (delta_c: its rows now).
Eigen::Vector3d local_solution(const LocalBlock& b, const Eigen::Vector3d& delta_c, const Eigen::Vector3d& lambda_c,
                               bool bilateral, double mu) {
  const Eigen::Matrix3d& Wcc = b.Wcc;
  const Eigen::Vector3d full = lambda_c - b.all.solve(delta_c);
  if (bilateral) return full;
  if (mu == 0) {
    // Normal row only; the tangential forces vanish.
    const double n = lambda_c[0] - (delta_c[0] + Wcc.row(0).tail<2>().dot(-lambda_c.tail<2>())) / Wcc(0, 0);
    return Eigen::Vector3d(std::max(0.0, n), 0, 0);
  }
  if (full[0] > 0 && full.tail<2>().norm() <= mu * full[0]) return full;  // sticks
  // Slides: the tangential force on the cone's edge, along the tangential trial force, and the
  // normal force that closes the gap with it; a normal force <= 0 means the contact separates.
  const Eigen::Vector2d trial =
      full[0] > 0 ? Eigen::Vector2d(full.tail<2>()) : Eigen::Vector2d(lambda_c.tail<2>() - b.tangential.solve(delta_c.tail<2>()));
  const Eigen::Vector2d d = trial.norm() > 0 ? Eigen::Vector2d(trial.normalized()) : Eigen::Vector2d::Zero();
  const double denominator = Wcc(0, 0) + mu * Wcc.row(0).tail<2>().dot(d);
  const double rhs = Wcc(0, 0) * lambda_c[0] + Wcc.row(0).tail<2>().dot(lambda_c.tail<2>()) - delta_c[0];
  const double n = std::max(0.0, denominator > 0 ? rhs / denominator : lambda_c[0] - delta_c[0] / Wcc(0, 0));
  Eigen::Vector3d out;
  out << n, mu * n * d;
  return out;
}

}  // namespace

ContactSolveResult solve_frictional_contacts(const Eigen::MatrixXd& W, const Eigen::VectorXd& delta0,
                                             const std::vector<char>& bilateral, double friction,
                                             double tolerance, int max_sweeps, Eigen::VectorXd& lambda) {
  ContactSolveResult result;
  const int m = static_cast<int>(bilateral.size());
  if (m == 0) {
    result.converged = true;
    return result;
  }
  Eigen::VectorXd delta = delta0;  // kept current as lambda changes
  // Kept between the solves of this thread: a frame allocates them only when its contacts
  // outnumber every earlier frame's.
  thread_local std::vector<LocalBlock> blocks;
  blocks.resize(m);
  for (int c = 0; c < m; ++c) {
    LocalBlock& b = blocks[c];
    b.Wcc = W.block<3, 3>(3 * c, 3 * c);
    b.all.compute(b.Wcc);
    if (friction > 0 && !bilateral[c]) b.tangential.compute(b.Wcc.bottomRightCorner<2, 2>());
  }
  Eigen::Vector3d change;
  for (result.sweeps = 1; result.sweeps <= max_sweeps; ++result.sweeps) {
    result.last_change = 0;
    for (int c = 0; c < m; ++c) {
      const Eigen::Vector3d updated =
          local_solution(blocks[c], delta.segment<3>(3 * c), lambda.segment<3>(3 * c), bilateral[c], friction);
      change = updated - lambda.segment<3>(3 * c);
      if (change.isZero(0.0)) continue;
      lambda.segment<3>(3 * c) = updated;
      delta.noalias() += W.middleCols<3>(3 * c) * change;
      result.last_change = std::max(result.last_change, (blocks[c].Wcc * change).cwiseAbs().maxCoeff());
    }
    if (result.last_change <= tolerance) {
      result.converged = true;
      break;
    }
  }
  result.sweeps = std::min(result.sweeps, max_sweeps);
  return result;
}

}  // namespace liver_sim
