// A cloud's points to the surface: closest points (exact, SurfaceLocator), the gate, the
// trimming and the Huber weights, the support a cloud must show, the fit's measures.
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "liver_sim/geometry/closest_points.h"
#include "liver_sim/geometry/node_positions.h"
#include "liver_sim/registration/registration.h"

namespace liver_sim {

int SurfaceRegistration::find_correspondences(bool new_cloud, const std::optional<Eigen::Vector3d>& viewpoint,
                                              RegistrationFrame& frame) {
  const int n = static_cast<int>(points_->size());
  if (new_cloud) {
    searched_at_.resize(0);
    locator_.build(model_.positions(), model_.boundary(), viewpoint);
  } else {
    locator_.refresh(model_.positions(), model_.boundary());
  }
  search_hits();
  ranked_.clear();
  for (int i = 0; i < n; ++i)
    if (hits_[i].distance <= options_.max_distance) ranked_.emplace_back(hits_[i].distance, i);
  // Trimmed: the farthest share of the gated points goes too (outliers near the surface).
  std::sort(ranked_.begin(), ranked_.end());
  ranked_.resize(ranked_.size() - static_cast<size_t>(options_.trim_fraction * ranked_.size()));
  // Coverage: the area of the triangles that hold an accepted point, of the whole boundary.
  const Eigen::VectorXd& x = model_.positions();
  const Eigen::MatrixX3i& F = model_.boundary();
  covered_.assign(F.rows(), 0);
  for (const auto& [d, i] : ranked_) covered_[hits_[i].triangle] = 1;
  double area = 0, covered_area = 0;
  for (int t = 0; t < F.rows(); ++t) {
    const double a = 0.5 * (node(x, F(t, 1)) - node(x, F(t, 0))).cross(node(x, F(t, 2)) - node(x, F(t, 0))).norm();
    area += a;
    if (covered_[t]) covered_area += a;
  }
  frame.coverage = covered_area / area;
  frame.inlier_fraction = n > 0 ? static_cast<double>(ranked_.size()) / n : 0.0;
  frame.stiffness_scale = std::min(1.0, frame.coverage / options_.full_coverage);
  auto huber = [&](double d) { return d <= options_.huber_width ? 1.0 : options_.huber_width / d; };
  double total_weight = 0;
  for (const auto& [d, i] : ranked_) total_weight += huber(d);
  targets_.clear();
  for (const auto& [d, i] : ranked_) {
    const SurfaceLocator::Hit& h = hits_[i];
    SurfaceTarget t;
    t.triangle = h.triangle;
    t.weights = h.weights;
    const pcl::PointXYZ& q = (*points_)[i];
    t.point = Eigen::Vector3d(q.x, q.y, q.z);
    if (options_.metric == RegistrationOptions::Metric::PointToPlane) t.normal = h.normal;
    t.stiffness = options_.stiffness * frame.stiffness_scale * huber(d) / total_weight;
    targets_.push_back(t);
  }
  return static_cast<int>(targets_.size());
}

std::string SurfaceRegistration::unsupported(int accepted, double coverage) const {
  std::ostringstream why;
  if (accepted < options_.min_points)
    why << accepted << " points correspond to the surface (registration.min_points: " << options_.min_points << ")";
  else if (coverage < options_.min_coverage)
    why << "the points cover " << 100 * coverage << "% of the surface (registration.min_coverage: "
        << 100 * options_.min_coverage << "%)";
  return why.str();
}

void SurfaceRegistration::search_hits() {
  const int n = static_cast<int>(points_->size());
  const double moved = surface_motion();
  const bool hits_known = std::isfinite(moved);  // the last search was of these points
  hits_.resize(n);
  for (int i = 0; i < n; ++i) {
    if (hits_known && still_beyond(hits_[i], moved)) {
      hits_[i].distance -= moved;  // still a lower bound
      continue;
    }
    const pcl::PointXYZ& q = (*points_)[i];
    hits_[i] = locator_.closest(Eigen::Vector3d(q.x, q.y, q.z), options_.max_distance, hits_known ? hits_[i].triangle : -1);
  }
  searched_at_ = model_.positions();
}

double SurfaceRegistration::all_points_rms() {
  const int n = static_cast<int>(points_->size());
  if (n == 0 || locator_.empty()) return 0.0;
  if (!std::isfinite(surface_motion())) {  // the hits are a refused cloud's
    locator_.refresh(model_.positions(), model_.boundary());
    search_hits();
  }
  // Each point's distance to the triangle its search found, at the current positions: no less
  // than its distance to the surface searched, and no more than that and twice the surface's
  // motion since the search (searching every point again would cost as much as the update).
  const Eigen::VectorXd& x = model_.positions();
  const Eigen::MatrixX3i& F = model_.boundary();
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const int t = hits_[i].triangle;
    if (t < 0) {  // beyond max_distance at the search
      sum += std::pow(options_.max_distance, 2);
      continue;
    }
    const pcl::PointXYZ& q = (*points_)[i];
    const Eigen::Vector3d p(q.x, q.y, q.z), a = node(x, F(t, 0)), b = node(x, F(t, 1)), c = node(x, F(t, 2));
    const Eigen::Vector3d w = closest_on_triangle(p, a, b, c);
    sum += std::pow(std::min((p - (w[0] * a + w[1] * b + w[2] * c)).norm(), options_.max_distance), 2);
  }
  return std::sqrt(sum / n);
}

double SurfaceRegistration::surface_motion() const {
  const Eigen::VectorXd& x = model_.positions();
  if (searched_at_.size() != x.size() || hits_.size() != points_->size()) return std::numeric_limits<double>::infinity();
  double moved = 0;
  for (Eigen::Index i = 0; i < x.size(); i += 3)
    moved = std::max(moved, (x.segment<3>(i) - searched_at_.segment<3>(i)).squaredNorm());
  return std::sqrt(moved);
}

bool SurfaceRegistration::still_beyond(const SurfaceLocator::Hit& hit, double moved) const {
  return hit.triangle < 0 && hit.distance - moved > options_.max_distance;
}

double SurfaceRegistration::spring_rms() const {
  const std::vector<SurfaceTarget>& targets = cloud_springs_;
  if (targets.empty()) return 0.0;
  const Eigen::VectorXd& x = model_.positions();
  const Eigen::MatrixX3i& F = model_.boundary();
  double sum = 0;
  for (const SurfaceTarget& t : targets) sum += t.stretch(x, F).squaredNorm();
  return std::sqrt(sum / targets.size());
}

}  // namespace liver_sim
