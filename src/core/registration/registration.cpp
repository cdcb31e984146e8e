#include "liver_sim/registration/registration.h"

#include <Eigen/SparseCore>
#include <pcl/registration/icp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>

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

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

Eigen::Vector3d node(const Eigen::VectorXd& x, int i) { return x.segment<3>(3 * i); }

bool finite(const pcl::PointXYZ& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); }

}  // namespace

std::vector<TrackedTarget> tracked_targets(const LiverModel& model) {
  std::vector<TrackedTarget> targets;
  for (int i = 0; i < model.num_probes(); ++i)
    targets.push_back({model.probe_name(i), TrackedTarget::Kind::Probe, model.probe_position(i)});
  if (model.num_beams() == 0) return targets;
  std::vector<int> degree(model.num_vessel_nodes(), 0), vessel(model.num_vessel_nodes(), 0);
  const Eigen::MatrixX2i& segments = model.beam_segments();
  for (int e = 0; e < segments.rows(); ++e)
    for (int end = 0; end < 2; ++end) {
      ++degree[segments(e, end)];
      vessel[segments(e, end)] = model.beam_vessel(e);
    }
  for (int k = 0; k < model.num_vessel_nodes(); ++k)
    if (degree[k] >= 3)
      targets.push_back({model.vessel_name(vessel[k]) + " bifurcation " + std::to_string(k),
                         TrackedTarget::Kind::Bifurcation, model.vessel_node_position(k)});
  return targets;
}

SurfaceRegistration::SurfaceRegistration(LiverModel& model, const RegistrationOptions& options)
    : model_(model),
      options_(options),
      points_(new pcl::PointCloud<pcl::PointXYZ>),
      previous_points_(new pcl::PointCloud<pcl::PointXYZ>) {
  const std::string error = validate(options);
  if (!error.empty()) throw std::invalid_argument(error);
  // Each candidate's free surface nodes, with a spring on a boundary triangle at each.
  const MechanicalModel& m = model.mechanics();
  const Eigen::VectorXd& X = m.rest_positions();
  const Eigen::MatrixX3i& F = m.boundary();
  std::vector<int> corner_triangle(X.size() / 3, -1), corner_slot(X.size() / 3, -1);
  Eigen::VectorXd area = Eigen::VectorXd::Zero(X.size() / 3);
  for (int t = 0; t < F.rows(); ++t) {
    const double a = 0.5 * (node(X, F(t, 1)) - node(X, F(t, 0))).cross(node(X, F(t, 2)) - node(X, F(t, 0))).norm();
    for (int j = 0; j < 3; ++j) {
      corner_triangle[F(t, j)] = t, corner_slot[F(t, j)] = j;
      area[F(t, j)] += a / 3;
    }
  }
  for (size_t c = 0; c < options.candidate_supports.size(); ++c) {
    Candidate candidate;
    double total = 0;
    for (int n : m.boundary_nodes()) {
      if (m.fixed_dofs()[3 * n] || !options.candidate_supports[c].contains(node(X, n))) continue;
      SurfaceTarget spring;
      spring.triangle = corner_triangle[n];
      spring.weights[corner_slot[n]] = 1.0;
      spring.point = node(X, n);
      spring.stiffness = options.support_stiffness;
      candidate.springs.push_back(spring);
      candidate.nodes.push_back(n);
      candidate.weights.push_back(area[n]);
      total += area[n];
    }
    if (candidate.nodes.empty())
      throw std::invalid_argument("registration.candidate_supports." + std::to_string(c) + ": the region selects no free surface node");
    for (double& w : candidate.weights) w /= total;
    supports_.push_back(std::move(candidate));
  }
  held_.assign(supports_.size(), false);
  gains_.assign(supports_.size(), 0.0);
  if (!supports_.empty() || options.estimates_tissue_stiffness() || options.estimate_hidden_loads)
    patches_ = make_surface_patches(model.mechanics(), options.uncertainty.patch_spacing);
  hidden_loads_.assign(patches_.centres.size(), Eigen::Vector3d::Zero());
  stepped_loads_ = hidden_loads_;
}

void SurfaceRegistration::apply_springs() {
  std::vector<SurfaceTarget> springs = cloud_springs_;
  for (size_t c = 0; c < supports_.size(); ++c)
    if (held_[c]) springs.insert(springs.end(), supports_[c].springs.begin(), supports_[c].springs.end());
  model_.set_surface_targets(std::move(springs));
}

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

std::string SurfaceRegistration::set_stiffness(double stiffness) {
  RegistrationOptions o = options_;
  o.stiffness = stiffness;
  const std::string error = validate(o);
  // Only the field changes: the node's cloud filter reads the others from another thread.
  if (error.empty()) options_.stiffness = stiffness;
  return error;
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
  Eigen::VectorXd loads = Eigen::VectorXd::Zero(model_.positions().size());
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

void SurfaceRegistration::clear() {
  model_.set_stiffness_scale(1.0);
  model_.set_surface_loads(Eigen::VectorXd());
  hidden_loads_.assign(patches_.centres.size(), Eigen::Vector3d::Zero());
  stepped_loads_ = hidden_loads_;
  model_.set_surface_targets({});
  cloud_springs_.clear();
  held_.assign(supports_.size(), false);
  gains_.assign(supports_.size(), 0.0);
  last_ = RegistrationFrame();
  updates_left_ = 0;
  alignment_ = Eigen::Isometry3d::Identity();
  aligned_ = false;
  points_->clear();
  searched_at_.resize(0);
  viewpoint_.reset();
}

std::string cloud_size_error(uint64_t points) {
  if (points <= kMaxCloudPoints) return "";
  return "a cloud of " + std::to_string(points) + " points: at most " + std::to_string(kMaxCloudPoints) + " are taken";
}

namespace {

constexpr int kMaxVoxelsPerAxis = 1 << 20;  // a 64-bit key holds three indices

Eigen::Array3d voxel_cells(double size, const Eigen::AlignedBox3d& box) {
  return (box.max() / size).array().floor() - (box.min() / size).array().floor() + 1;
}

}  // namespace

std::string voxel_grid_error(double voxel, const Eigen::AlignedBox3d& box) {
  // Negated: a voxel so fine that the box's cell indices overflow to infinity (inf - inf: NaN)
  // is refused too.
  if (!(voxel > 0) || (voxel_cells(voxel, box) <= kMaxVoxelsPerAxis).all()) return "";
  std::ostringstream m;
  m << "a voxel of " << voxel << " m is too fine for a box of " << box.sizes().maxCoeff() << " m: at most "
    << kMaxVoxelsPerAxis << " voxels along an axis";
  return m.str();
}

namespace {

// The centroids of a cloud's points per voxel of a grid aligned at multiples of `size` (m), as
// PCL's VoxelGrid gives them. Its voxels are found by hashing, in one pass: VoxelGrid sorts
// every point by its voxel (with the crop, 10.6 ms against 1.4 ms for 100,000 points in 5 mm
// voxels on one core).
class VoxelCentroids {
 public:
  // Points to come lie in `box` (throws std::invalid_argument with voxel_grid_error's refusal).
  VoxelCentroids(double size, const Eigen::AlignedBox3d& box) : size_(size) {
    const std::string too_fine = voxel_grid_error(size, box);
    if (!too_fine.empty()) throw std::invalid_argument(too_fine);
    lower_ = (box.min() / size).array().floor();
    const Eigen::Array3d cells = voxel_cells(size, box);
    row_ = static_cast<int64_t>(cells.x());
    layer_ = row_ * static_cast<int64_t>(cells.y());
    rehash(1024);
  }
  void add(const Eigen::Vector3d& p) {
    const Eigen::Array3d cell = (p / size_).array().floor() - lower_;
    const int64_t key = static_cast<int64_t>(cell.x()) + row_ * static_cast<int64_t>(cell.y()) +
                        layer_ * static_cast<int64_t>(cell.z());
    size_t i = bucket(key);
    while (keys_[i] >= 0 && keys_[i] != key) i = (i + 1) & (keys_.size() - 1);
    if (keys_[i] < 0) {
      keys_[i] = key;
      voxel_[i] = static_cast<int>(sums_.size());
      sums_.emplace_back(Eigen::Vector3d::Zero(), 0);
      if (2 * sums_.size() > keys_.size()) {  // at most half full: short probes
        rehash(2 * keys_.size());
        i = bucket(key);
        while (keys_[i] != key) i = (i + 1) & (keys_.size() - 1);
      }
    }
    auto& [sum, count] = sums_[voxel_[i]];
    sum += p;
    ++count;
  }
  // The centroids, in the order of their voxels (x fastest, then y, then z).
  void centroids(pcl::PointCloud<pcl::PointXYZ>& out) const {
    std::vector<std::pair<int64_t, int>> order;
    order.reserve(sums_.size());
    for (size_t i = 0; i < keys_.size(); ++i)
      if (keys_[i] >= 0) order.emplace_back(keys_[i], voxel_[i]);
    std::sort(order.begin(), order.end());
    out.clear();
    out.reserve(order.size());
    for (const auto& [key, v] : order) {
      const Eigen::Vector3d c = sums_[v].first / sums_[v].second;
      out.push_back(pcl::PointXYZ(c.x(), c.y(), c.z()));
    }
  }

 private:
  size_t bucket(int64_t key) const {
    return static_cast<size_t>((static_cast<uint64_t>(key) * 0x9E3779B97F4A7C15ull) >> shift_);
  }
  void rehash(size_t capacity) {
    std::vector<int64_t> keys(capacity, -1);
    std::vector<int> voxel(capacity);
    keys_.swap(keys);
    voxel_.swap(voxel);
    shift_ = 64 - static_cast<int>(std::log2(static_cast<double>(capacity)));
    for (size_t j = 0; j < keys.size(); ++j) {
      if (keys[j] < 0) continue;
      size_t i = bucket(keys[j]);
      while (keys_[i] >= 0) i = (i + 1) & (capacity - 1);
      keys_[i] = keys[j];
      voxel_[i] = voxel[j];
    }
  }
  double size_;
  Eigen::Array3d lower_;
  int64_t row_ = 0, layer_ = 0;
  std::vector<int64_t> keys_;  // open addressing, linear probing; -1: empty
  std::vector<int> voxel_;     // per bucket: its index in sums_
  int shift_ = 0;
  std::vector<std::pair<Eigen::Vector3d, int>> sums_;  // per voxel: its points' sum and count
};

}  // namespace

int prepare_cloud(const pcl::PointCloud<pcl::PointXYZ>& in, const Eigen::Isometry3d& transform,
                  const Eigen::AlignedBox3d& box, double voxel, int max_points, pcl::PointCloud<pcl::PointXYZ>& out) {
  const std::string too_large = cloud_size_error(in.size());
  if (!too_large.empty()) throw std::invalid_argument(too_large);
  std::optional<VoxelCentroids> grid;
  if (voxel > 0) grid.emplace(voxel, box);
  out.clear();
  if (!grid) out.reserve(in.size());
  int finite_points = 0;
  for (const pcl::PointXYZ& q : in) {
    if (!finite(q)) continue;
    ++finite_points;
    const Eigen::Vector3d p = transform * Eigen::Vector3d(q.x, q.y, q.z);
    if (!box.contains(p)) continue;
    if (grid)
      grid->add(p);
    else
      out.push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  }
  if (grid) grid->centroids(out);
  if (static_cast<int>(out.size()) > max_points) {
    const double stride = static_cast<double>(out.size()) / max_points;
    pcl::PointCloud<pcl::PointXYZ> kept;
    for (int i = 0; i < max_points; ++i) kept.push_back(out[static_cast<size_t>(i * stride)]);
    out.swap(kept);
  }
  return finite_points;
}

int SurfaceRegistration::filter(const pcl::PointCloud<pcl::PointXYZ>& cloud) {
  // Only points within max_distance of the model's box can correspond; cropping first also
  // bounds the voxel grid (voxel_grid_error).
  const Eigen::VectorXd& x = model_.positions();
  Eigen::AlignedBox3d box;
  for (int i = 0; i < x.size(); i += 3) box.extend(x.segment<3>(i));
  box.min().array() -= options_.max_distance;
  box.max().array() += options_.max_distance;
  return prepare_cloud(cloud, alignment_, box, options_.voxel_size, options_.max_points, *points_);
}

void SurfaceRegistration::align_rigidly() {
  // Point-to-plane ICP against the boundary at the current state, sampled on a barycentric grid
  // of about 2 mm with the triangles' normals: distances to the tangent planes are distances to
  // the surface, where distances to the samples would bias the fit by the grid's spacing.
  const Eigen::VectorXd& x = model_.positions();
  const Eigen::MatrixX3i& F = model_.boundary();
  auto surface = pcl::make_shared<pcl::PointCloud<pcl::PointNormal>>();
  for (int t = 0; t < F.rows(); ++t) {
    const Eigen::Vector3d a = node(x, F(t, 0)), b = node(x, F(t, 1)), c = node(x, F(t, 2));
    const Eigen::Vector3d normal = (b - a).cross(c - a).normalized();
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int n = std::max(1, static_cast<int>(std::ceil(longest / 2e-3)));
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const Eigen::Vector3d p = a + (b - a) * (static_cast<double>(i) / n) + (c - a) * (static_cast<double>(j) / n);
        pcl::PointNormal q;
        q.getVector3fMap() = p.cast<float>();
        q.getNormalVector3fMap() = normal.cast<float>();
        surface->push_back(q);
      }
  }
  auto source = pcl::make_shared<pcl::PointCloud<pcl::PointNormal>>();
  for (const pcl::PointXYZ& p : *points_) {
    pcl::PointNormal q;
    q.getVector3fMap() = p.getVector3fMap();
    q.getNormalVector3fMap().setZero();
    source->push_back(q);
  }
  pcl::IterativeClosestPointWithNormals<pcl::PointNormal, pcl::PointNormal> icp;
  icp.setInputSource(source);
  icp.setInputTarget(surface);
  icp.setMaxCorrespondenceDistance(5 * options_.max_distance);
  icp.setMaximumIterations(200);
  icp.setTransformationEpsilon(1e-14);
  icp.setEuclideanFitnessEpsilon(0);
  pcl::PointCloud<pcl::PointNormal> moved;
  icp.align(moved);
  if (!icp.hasConverged()) return;  // left unaligned; the next cloud tries again
  const Eigen::Isometry3d step(icp.getFinalTransformation().cast<double>());
  alignment_ = step * alignment_;
  for (size_t i = 0; i < moved.size(); ++i) (*points_)[i].getVector3fMap() = moved[i].getVector3fMap();
  aligned_ = true;
  align_requested_ = false;
}

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

RegistrationFrame SurfaceRegistration::register_cloud(const pcl::PointCloud<pcl::PointXYZ>& cloud,
                                                      const std::optional<Eigen::Vector3d>& viewpoint) {
  const auto t_frame = frame_start_ = Clock::now();
  RegistrationFrame frame;
  if (viewpoint && !viewpoint->allFinite()) throw std::invalid_argument("the viewpoint is not finite");
  // The points of the previous frame, their hits and their remaining updates stay in use if
  // this cloud is refused (swapped, not copied).
  points_.swap(previous_points_);
  hits_.swap(previous_hits_);
  searched_at_.swap(previous_searched_at_);
  searched_at_.resize(0);  // no hits of points_ yet
  const auto keep_last_cloud = [&] {
    points_.swap(previous_points_);
    hits_.swap(previous_hits_);
    searched_at_.swap(previous_searched_at_);
  };
  try {
    frame.input_points = filter(cloud);
  } catch (...) {  // a cloud too large, a voxel too fine for its box
    keep_last_cloud();
    throw;
  }
  if (points_->empty()) {
    keep_last_cloud();
    throw std::invalid_argument(frame.input_points == 0 ? "the cloud has no finite point"
                                                        : "no point of the cloud lies near the model");
  }
  // Until the first springs are set, a refusal or a fault (a step that threw and was rolled
  // back, memory) restores the last cloud, the locator, the viewpoint and the alignment.
  const Eigen::Isometry3d previous_alignment = alignment_;
  const bool was_aligned = aligned_, was_requested = align_requested_;
  const std::optional<Eigen::Vector3d> previous_viewpoint = viewpoint_;
  std::swap(locator_, previous_locator_);
  try {
    if ((options_.rigid_alignment && !aligned_) || align_requested_) align_rigidly();
    frame.used_points = static_cast<int>(points_->size());
    frame.filter_ms = ms_since(t_frame);
    const std::optional<Eigen::Vector3d> eye = viewpoint ? std::optional<Eigen::Vector3d>(alignment_ * *viewpoint) : viewpoint;
    const auto t0 = Clock::now();
    const int found = find_correspondences(true, eye, frame);
    frame.correspondence_ms += ms_since(t0);
    if (found == 0)
      throw std::invalid_argument(locator_.empty() ? "no surface triangle faces the viewpoint (a sensor inside the liver?)"
                                                   : "no point of the cloud lies within max_distance of the surface");
    const std::string why = unsupported(found, frame.coverage);
    if (!why.empty()) throw std::invalid_argument(why);
    viewpoint_ = eye;
    accept_update(found, frame);
  } catch (...) {
    keep_last_cloud();
    std::swap(locator_, previous_locator_);
    viewpoint_ = previous_viewpoint;
    alignment_ = previous_alignment;
    aligned_ = was_aligned;
    align_requested_ = was_requested;
    throw;
  }
  updates_left_ = frame.step.status != StepResult::Status::Diverged ? options_.correspondence_updates - 1 : 0;
  try {
    continue_updates(options_.frame_updates - 1, frame);
  } catch (...) {  // the cloud stands with its last update that stepped
    finish(frame, t_frame);
    throw;
  }
  finish(frame, t_frame);
  return frame;
}

void SurfaceRegistration::finish(RegistrationFrame& frame, Clock::time_point start) {
  frame.rms = spring_rms();
  frame.rms_all = all_points_rms();
  frame.total_ms = ms_since(start);
  last_ = frame;
}

void SurfaceRegistration::solve(RegistrationFrame& frame) {
  const auto t0 = Clock::now();
  const SolverOptions scene_solver = model_.solver_options();
  SolverOptions frame_solver = scene_solver;
  frame_solver.strategy = options_.strategy;
  frame_solver.max_iterations = options_.newton_iterations;
  // The scene's time budget is the frame's: the search and the solves before took their share.
  auto budget_left = [&] { return std::max(scene_solver.time_budget - ms_since(frame_start_) / 1000, 1e-6); };
  frame_solver.time_budget = budget_left();
  model_.set_solver_options(frame_solver);  // valid: the scene's with validated values
  // The scene's options again however the solve ends (a step may throw: the model is rolled
  // back and the exception goes on to the caller).
  struct SceneOptions {
    LiverModel& model;
    const SolverOptions& options;
    ~SceneOptions() { model.set_solver_options(options); }
  } scene_options{model_, scene_solver};
  frame.step = model_.step();
  // An iteration on a factor from before the springs moved may not descend, and the step is
  // rolled back (stalled). Once more, on a fresh factor, and with the hidden loads of the last
  // step that did not diverge: a step of the loads' fit is linearised and may go too far.
  if (frame.step.status == StepResult::Status::Diverged) {
    frame.newton_iterations += frame.step.iterations;
    frame.factorizations += frame.step.factorizations;
    if (hidden_loads_ != stepped_loads_) {
      hidden_loads_ = stepped_loads_;
      set_model_loads();
      frame.hidden_loads_reverted = true;
    }
    model_.refactorize();
    frame_solver.time_budget = budget_left();
    model_.set_solver_options(frame_solver);
    frame.step = model_.step();
  }
  frame.solve_ms += ms_since(t0);
  frame.newton_iterations += frame.step.iterations;
  frame.factorizations += frame.step.factorizations;
  note_step(frame.step);
}

void SurfaceRegistration::accept_update(int found, RegistrationFrame& frame) {
  cloud_springs_.swap(targets_);  // targets_ is refilled at the next update
  apply_springs();
  try {
    solve(frame);
  } catch (...) {  // the step that threw was rolled back (NewtonStepper): so are the springs it solved
    cloud_springs_.swap(targets_);
    apply_springs();
    throw;
  }
  frame.correspondences = found;
  ++frame.updates;
}

void SurfaceRegistration::continue_updates(int count, RegistrationFrame& frame) {
  // A frame that has solved once and spent its time budget (a factorisation takes more than a
  // 30 Hz frame on the phantom) leaves its remaining updates to the next refine() calls: the
  // next cloud waits for one frame, not for all of them.
  const double budget_s = model_.solver_options().time_budget;
  const auto time_left = [&] { return frame.updates == 0 || ms_since(frame_start_) / 1000 < budget_s; };
  for (; count > 0 && updates_left_ > 0 && time_left(); --count) {
    const auto t0 = Clock::now();
    const double coverage = frame.coverage, inlier_fraction = frame.inlier_fraction, scale = frame.stiffness_scale;
    const int found = find_correspondences(false, std::nullopt, frame);
    frame.correspondence_ms += ms_since(t0);
    const auto keep_last_springs = [&] {
      frame.coverage = coverage;
      frame.inlier_fraction = inlier_fraction;
      frame.stiffness_scale = scale;
    };
    if (!unsupported(found, frame.coverage).empty()) {  // the surface moved away from the points: the last springs stay
      keep_last_springs();
      updates_left_ = 0;
      return;
    }
    try {
      accept_update(found, frame);
    } catch (...) {  // the update is left for the next call to try again
      keep_last_springs();
      throw;
    }
    updates_left_ = frame.step.status == StepResult::Status::Diverged ? 0 : updates_left_ - 1;
  }
}

RegistrationFrame SurfaceRegistration::refine() {
  const auto t_frame = frame_start_ = Clock::now();
  RegistrationFrame frame;
  frame.input_points = last_.input_points;
  frame.used_points = static_cast<int>(points_->size());
  frame.correspondences = static_cast<int>(cloud_springs_.size());
  frame.inlier_fraction = last_.inlier_fraction;
  frame.coverage = last_.coverage;
  frame.stiffness_scale = last_.stiffness_scale;
  // An update that finds the points no longer supported leaves the springs: they are solved.
  const auto adopt = [&] {
    if (frame.updates == 0) return false;
    last_.correspondences = frame.correspondences;
    last_.coverage = frame.coverage;
    last_.inlier_fraction = frame.inlier_fraction;
    last_.stiffness_scale = frame.stiffness_scale;
    return true;
  };
  try {
    continue_updates(options_.frame_updates, frame);
  } catch (...) {  // the springs are those of the last update that stepped
    adopt();
    throw;
  }
  if (!adopt()) {
    solve(frame);
  }
  frame.rms = spring_rms();
  frame.rms_all = all_points_rms();
  frame.total_ms = ms_since(t_frame);
  return frame;
}

}  // namespace liver_sim
