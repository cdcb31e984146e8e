// Conjugate gradients on the tangent at the iterate with the Jacobi preconditioner (the
// matrix's inverse diagonal): no factor at all (SolverOptions::Strategy::CG).
#include "liver_sim/linalg/conjugate_gradient.h"
#include "update_strategy.h"

namespace liver_sim {
namespace {

class JacobiCG final : public UpdateStrategy {
 public:
  using UpdateStrategy::UpdateStrategy;
  bool factorizes() const override { return false; }
  bool current_tangent() const override { return true; }

  int solve(const NewtonIteration& it, Eigen::VectorXd& dx) override {
    const NewtonMatrix& A = parts_.matrix;
    jacobi_.resize(A.pattern().rows());
    for (int i = 0; i < A.pattern().rows(); ++i) jacobi_[i] = 1.0 / A.values()[A.pattern().diagonal(i)];
    const Gmres::Operator tangent = [this](const Eigen::VectorXd& v, Eigen::VectorXd& out) {
      parts_.matrix.multiply(v, out);
    };
    const Gmres::Operator jacobi = [this](const Eigen::VectorXd& in, Eigen::VectorXd& out) {
      out = jacobi_.cwiseProduct(in);
    };
    // Without a factor it needs many more iterations than the preconditioned solves.
    return cg_.solve(tangent, jacobi, it.r, dx, it.forcing, 20 * kMaxKrylov * kMaxKrylov, it.deadline);
  }

 private:
  ConjugateGradient cg_;
  Eigen::VectorXd jacobi_;  // inverse diagonal of the matrix
};

}  // namespace

std::unique_ptr<UpdateStrategy> make_jacobi_cg(const StrategyParts& parts) {
  return std::make_unique<JacobiCG>(parts);
}

}  // namespace liver_sim
