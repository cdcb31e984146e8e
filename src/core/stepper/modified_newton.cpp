// Modified Newton: the factor of an earlier tangent solved directly, with contacts the contact
// forces in the same solve (the direct contact update); refreshed when an iteration contracts
// the residual too little, in the step or, with SolverOptions::background_refresh, on a thread
// of its own while the old factor serves.
#include "update_strategy.h"

namespace liver_sim {
namespace {

// A factor whose iteration leaves more than this share of the residual it was asked to zero
// is refreshed; with a change of the contact forces the stricter share (bench, probe sweeps on
// the cube and the phantom: 0.3-0.9 tried, doc/performance.md).
constexpr double kContraction = 0.9, kContactContraction = 0.5;

class ModifiedNewton final : public UpdateStrategy {
 public:
  using UpdateStrategy::UpdateStrategy;
  SolverOptions::Strategy with_contacts() const override { return SolverOptions::Strategy::ModifiedNewton; }
  bool factorizes() const override { return !parts_.factor.valid(); }
  bool current_tangent() const override { return false; }
  int solve(const NewtonIteration& it, Eigen::VectorXd& dx) override { return direct_solve(it, dx); }
  bool scales_contact_forces() const override { return true; }
  bool redoes_without_descent() const override { return true; }

  // The factor is kept while it contracts the residual well: the residual it was asked to zero,
  // which carries the update's change of the contact forces (a step that closes new gaps raises
  // the residual it started from). When contact forces changed, the factor also set them
  // (through the Delassus operator), so an old one errs in the forces more than its residual
  // shows: it must contract further. A factor is judged by the iterations after the one that
  // made it: that one's contraction measures how far the problem is from linear here (contacts
  // coming and going), which a factor made one iteration later meets as well. In the soak's
  // frames a fresh factor left more than half of the residual about as often as an older one
  // (33% and 29% of the iterations with contact forces changing).
  void end_iteration(const IterationEnd& end) override {
    double asked = end.start_norm, contraction = kContraction;
    if (end.contact_forces_scaled) {
      asked_ = end.r_start;
      if (parts_.contact.add_force_change(asked_)) contraction = kContactContraction;
      const std::vector<char>& fixed = parts_.mechanics.fixed_dofs();
      for (int i = 0; i < asked_.size(); ++i)
        if (fixed[i]) asked_[i] = 0;
      asked = asked_.norm();
    }
    if (end.end_norm <= contraction * asked || end.fresh_factor) return;
    // A factor that no longer contracts at all is not kept waiting for the background (which a
    // busy processor may hold up for many frames): refreshed in the step.
    if (end.end_norm > asked)
      parts_.factor.mark_stale();
    else
      refresh();
  }

 private:
  Eigen::VectorXd asked_;  // the residual the iteration was asked to zero
};

}  // namespace

std::unique_ptr<UpdateStrategy> make_modified_newton(const StrategyParts& parts) {
  return std::make_unique<ModifiedNewton>(parts);
}

}  // namespace liver_sim
