#include "liver_sim/registration/registration.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "liver_sim/geometry/node_positions.h"

namespace liver_sim {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

}  // namespace

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

std::string SurfaceRegistration::set_stiffness(double stiffness) {
  RegistrationOptions o = options_;
  o.stiffness = stiffness;
  const std::string error = validate(o);
  // Only the field changes: the node's cloud filter reads the others from another thread.
  if (error.empty()) options_.stiffness = stiffness;
  return error;
}

void SurfaceRegistration::clear() {
  model_.set_stiffness_scale(1.0);
  shape_loads_.resize(0);
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

SurfaceRegistration::OneShotReport SurfaceRegistration::register_one_shot(OneShotRegistration& one_shot,
                                                                       const pcl::PointCloud<pcl::PointXYZ>& cloud,
                                                                       const std::optional<Eigen::Vector3d>& viewpoint) {
  if (one_shot.model().mesh().V != model_.mesh().V || one_shot.model().mesh().T != model_.mesh().T)
    throw std::invalid_argument("the one-shot registration's model has another mesh");
  OneShotReport report;
  report.one_shot = one_shot.solve(cloud, viewpoint, alignment_);
  report.frame = adopt_one_shot(report.one_shot, cloud, viewpoint, model_.contact().forces(model_.positions()));
  return report;
}

RegistrationFrame SurfaceRegistration::adopt_one_shot(const OneShotResult& result,
                                                      const pcl::PointCloud<pcl::PointXYZ>& cloud,
                                                      const std::optional<Eigen::Vector3d>& viewpoint,
                                                      const Eigen::VectorXd& instrument_forces) {
  if (result.positions.size() != model_.positions().size() || !result.positions.allFinite())
    throw std::invalid_argument("the one-shot registration's shape is not the model's");
  if (instrument_forces.size() != result.positions.size() || !instrument_forces.allFinite())
    throw std::invalid_argument("the instruments' forces at the one-shot registration's reference are not the model's");
  clear();
  const Eigen::VectorXd& x = result.positions;
  model_.set_positions(x);
  Eigen::VectorXd internal, external;
  MechanicalModel& m = model_.mechanics();
  m.internal_forces(x, internal);
  m.external_forces(x, external);
  // The instruments in the model press by themselves: their reaction at the reference, which
  // the one-shot's shape carries, held by a constant load would stay where they pressed.
  shape_loads_ = internal - model_.load_scale() * external;
  shape_loads_ -= instrument_forces;
  set_model_loads();
  stepped_loads_ = hidden_loads_;
  alignment_ = result.alignment;
  aligned_ = true;
  align_requested_ = false;
  return register_cloud(cloud, viewpoint);
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
  // The model converges on a cloud over the frames that follow it (refine()), not in this one.
  frame_solver.capped_residual = std::numeric_limits<double>::infinity();
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
