#include "liver_sim/registration/one_shot.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "liver_sim/geometry/node_positions.h"
#include "liver_sim/registration/cloud_filter.h"
#include "liver_sim/registration/cloud_normals.h"

namespace liver_sim {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

std::string check(bool ok, const std::string& field, const std::string& bound, double value) {
  if (ok) return "";
  std::ostringstream m;
  m << "one_shot." << field << ": " << value << " is not " << bound;
  return m.str();
}

// The scene without what the one-shot registration does not assume: supports (unknown), scene
// loads (the shape is registered as it is, its weight included), instruments. Dynamic only so
// that a model without supports is accepted: it is never stepped.
Scene free_scene(Scene scene) {
  scene.fixed.clear();
  scene.loads.clear();
  scene.instruments.clear();
  scene.solver.mode = SolverOptions::Mode::Dynamic;
  return scene;
}

// The rigid motion x -> c + t + R(w) (x - c) of a small rotation vector w about c.
Eigen::Isometry3d rigid_step(const Eigen::Vector3d& c, const Eigen::Vector3d& w, const Eigen::Vector3d& t) {
  Eigen::Isometry3d step = Eigen::Isometry3d::Identity();
  if (w.norm() > 0) step.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix();
  step.translation() = c + t - step.linear() * c;
  return step;
}

}  // namespace

std::string validate(const OneShotOptions& o) {
  const std::string errors[] = {
      check(o.voxel_size >= 0 && o.voxel_size <= 0.1, "voxel_size", "in [0, 0.1] m", o.voxel_size),
      check(o.max_points >= 50 && o.max_points <= 100000, "max_points", "in [50, 100000]", o.max_points),
      check(o.normal_neighbours >= 4 && o.normal_neighbours <= 100, "normal_neighbours", "in [4, 100]", o.normal_neighbours),
      check(o.start_gate > 0 && o.start_gate <= 1, "start_gate", "in (0, 1] m", o.start_gate),
      check(o.end_gate > 0 && o.end_gate <= o.start_gate, "end_gate", "in (0, start_gate] m", o.end_gate),
      check(o.max_normal_angle > 0 && o.max_normal_angle <= M_PI, "max_normal_angle", "in (0, pi] rad", o.max_normal_angle),
      check(o.trim_fraction >= 0 && o.trim_fraction < 0.9, "trim_fraction", "in [0, 0.9)", o.trim_fraction),
      check(o.huber_width > 0 && std::isfinite(o.huber_width), "huber_width", "> 0 m", o.huber_width),
      check(o.rigid_iterations >= 0 && o.rigid_iterations <= 1000, "rigid_iterations", "in [0, 1000]", o.rigid_iterations),
      check(o.patch_spacing >= 1e-3 && o.patch_spacing <= 1, "patch_spacing", "in [1e-3, 1] m", o.patch_spacing),
      check(o.load_damping >= 1e-9 && o.load_damping <= 1e3, "load_damping", "in [1e-9, 1e3]", o.load_damping),
      check(o.start_damping >= o.load_damping && o.start_damping <= 1e3, "start_damping", "in [load_damping, 1e3]",
            o.start_damping),
      check(o.foundation > 0 && o.foundation <= 10, "foundation", "in (0, 10]", o.foundation),
      check(o.support >= 0 && o.support <= 1e3, "support", "in [0, 1e3]", o.support),
      check(o.rounds >= 1 && o.rounds <= 20, "rounds", "in [1, 20]", o.rounds),
      check(o.iterations >= 1 && o.iterations <= 100, "iterations", "in [1, 100]", o.iterations),
      check(o.posterior_scale >= 0 && std::isfinite(o.posterior_scale), "posterior_scale", ">= 0", o.posterior_scale),
      check(o.damping_error >= 0 && std::isfinite(o.damping_error), "damping_error", ">= 0", o.damping_error),
      check(o.model_error_floor >= 0 && std::isfinite(o.model_error_floor), "model_error_floor", ">= 0 m", o.model_error_floor),
      check(o.displacement_error >= 0 && o.displacement_error <= 1, "displacement_error", "in [0, 1]", o.displacement_error)};
  for (const std::string& e : errors)
    if (!e.empty()) return e;
  return "";
}

OneShotRegistration::OneShotRegistration(const TetMesh& mesh, const Scene& scene, const OneShotOptions& options)
    : options_(options),
      model_([&] {
        const std::string error = validate(options);
        if (!error.empty()) throw std::invalid_argument(error);
        return std::make_unique<LiverModel>(mesh, free_scene(scene));
      }()),
      compliance_(*model_) {
  MechanicalModel& m = model_->mechanics();
  const Eigen::VectorXd& X = m.rest_positions();
  const Eigen::MatrixX3i& F = m.boundary();
  // The foundation: a spring from each surface node to its rest position, stiffness per area
  // foundation x E / L.
  double volume = 0;
  for (int e = 0; e < mesh.T.rows(); ++e) {
    Eigen::Matrix3d edges;
    for (int k = 1; k < 4; ++k) edges.col(k - 1) = node(X, mesh.T(e, k)) - node(X, mesh.T(e, 0));
    volume += std::abs(edges.determinant()) / 6;
  }
  // Where the scene's supports hold it, the spring is support x E / L per area stiffer: held
  // softly, so that the cloud may still move an attachment the segmentation placed wrongly.
  const double unit = scene.parenchyma.young_modulus / std::cbrt(volume);
  std::vector<char> supported(X.size() / 3, 0);
  for (int i = 0; i < static_cast<int>(supported.size()); ++i)
    for (const Region& r : scene.fixed) supported[i] = supported[i] || r.contains(node(X, i));
  std::vector<SurfaceTarget> foundation(X.size() / 3);
  for (int t = 0; t < F.rows(); ++t) {
    const double a = 0.5 * (node(X, F(t, 1)) - node(X, F(t, 0))).cross(node(X, F(t, 2)) - node(X, F(t, 0))).norm();
    for (int j = 0; j < 3; ++j) {
      SurfaceTarget& s = foundation[F(t, j)];
      s.triangle = t;
      s.weights = Eigen::Vector3d::Unit(j);
      s.point = node(X, F(t, j));
      s.stiffness += (options.foundation + (supported[F(t, j)] ? options.support : 0.0)) * unit * a / 3;
    }
  }
  foundation.erase(std::remove_if(foundation.begin(), foundation.end(), [](const SurfaceTarget& s) { return s.triangle < 0; }),
                   foundation.end());
  model_->set_surface_targets(std::move(foundation));
  reference_ = X;
  reference_loads_ = Eigen::VectorXd::Zero(X.size());
  patches_ = make_surface_patches(m, options.patch_spacing);
  unit_loads_ = Eigen::MatrixXd::Zero(X.size(), 3 * patches_.centres.size());
  for (size_t p = 0; p < patches_.centres.size(); ++p)
    for (size_t i = 0; i < patches_.nodes[p].size(); ++i)
      for (int a = 0; a < 3; ++a) unit_loads_(3 * patches_.nodes[p][i] + a, 3 * p + a) = patches_.weights[p][i];
}

double OneShotRegistration::schedule(double start, double end, double t) const {
  return start * std::pow(end / start, std::clamp(t, 0.0, 1.0));
}

std::vector<OneShotRegistration::Match> OneShotRegistration::match(const Eigen::VectorXd& y,
                                                                   const Eigen::Isometry3d& alignment, double gate,
                                                                   bool same_side) {
  locator_.refresh(y, model_->boundary());
  const double min_cos = same_side ? std::cos(options_.max_normal_angle) : -1.0;
  std::vector<std::pair<double, Match>> found;
  for (int i = 0; i < static_cast<int>(points_.size()); ++i) {
    const Eigen::Vector3d q = alignment * points_[i].getVector3fMap().cast<double>();
    const SurfaceLocator::Hit hit = locator_.closest(q, gate);
    if (hit.triangle < 0) continue;
    if (!normals_[i].isZero(0.0) && (alignment.linear() * normals_[i]).dot(hit.normal) < min_cos) continue;
    found.push_back({hit.distance, {i, hit, 1.0}});
  }
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  found.resize(found.size() - static_cast<size_t>(options_.trim_fraction * found.size()));
  std::vector<Match> matches;
  for (auto& [d, m] : found) {
    m.weight = d <= options_.huber_width ? 1.0 : options_.huber_width / d;
    matches.push_back(m);
  }
  return matches;
}

void OneShotRegistration::set_reference(const Eigen::VectorXd& positions) {
  MechanicalModel& m = model_->mechanics();
  if (positions.size() != m.rest_positions().size() || !positions.allFinite())
    throw std::invalid_argument("the one-shot registration's reference is not a finite state of the model");
  std::vector<SurfaceTarget> foundation = model_->surface_targets();
  const Eigen::MatrixX3i& F = m.boundary();
  for (SurfaceTarget& s : foundation) {
    s.point.setZero();
    for (int j = 0; j < 3; ++j) s.point += s.weights[j] * node(positions, F(s.triangle, j));
  }
  model_->set_surface_targets(std::move(foundation));
  reference_ = positions;
  Eigen::VectorXd internal, external;
  m.internal_forces(reference_, internal);
  m.external_forces(reference_, external);
  reference_loads_ = internal - model_->load_scale() * external;
}

OneShotResult OneShotRegistration::solve(const pcl::PointCloud<pcl::PointXYZ>& cloud,
                                         const std::optional<Eigen::Vector3d>& viewpoint, const Eigen::Isometry3d& start) {
  const auto t0 = Clock::now();
  OneShotResult result;
  const Eigen::VectorXd& X = reference_;
  Eigen::AlignedBox3d box;
  for (Eigen::Index i = 0; i < X.size(); i += 3) box.extend(X.segment<3>(i));
  box.min().array() -= options_.start_gate;
  box.max().array() += options_.start_gate;
  // Filtered in the cloud's own frame: the box, moved back there, bounds the voxel grid.
  pcl::PointCloud<pcl::PointXYZ> moved;
  result.input_points = prepare_cloud(cloud, start, box, options_.voxel_size, options_.max_points, moved);
  if (moved.empty())
    throw std::invalid_argument(result.input_points == 0 ? "the cloud has no finite point"
                                                         : "no point of the cloud lies within one_shot.start_gate of the model");
  const Eigen::Isometry3d back = start.inverse();
  points_.clear();
  for (const pcl::PointXYZ& p : moved) {
    const Eigen::Vector3f q = (back * p.getVector3fMap().cast<double>()).cast<float>();
    points_.push_back(pcl::PointXYZ(q.x(), q.y(), q.z()));
  }
  result.used_points = static_cast<int>(points_.size());
  normals_ = estimate_normals(points_, options_.normal_neighbours, viewpoint);
  alignment_ = start;
  model_->set_positions(X);
  loads_ = Eigen::VectorXd::Zero(unit_loads_.cols());
  model_->set_surface_loads(reference_loads_);
  locator_.build(X, model_->boundary(), viewpoint ? std::optional<Eigen::Vector3d>(start * *viewpoint) : std::nullopt);
  if (!viewpoint) {
    // One side for the whole cloud: the one most points agree with the surface on.
    int agree = 0, votes = 0;
    for (const Match& m : match(X, alignment_, options_.start_gate, /*same_side=*/false))
      if (!normals_[m.point].isZero(0.0)) {
        agree += (start.linear() * normals_[m.point]).dot(m.hit.normal) > 0;
        ++votes;
      }
    if (2 * agree < votes)
      for (Eigen::Vector3d& n : normals_) n = -n;
  }
  result.filter_ms = ms_since(t0);
  const auto t1 = Clock::now();
  rigid_stage(result);
  result.rigid_ms = ms_since(t1);
  const auto t2 = Clock::now();
  deformation_stage(result);
  result.deform_ms = ms_since(t2);
  result.total_ms = ms_since(t0);
  return result;
}

void OneShotRegistration::rigid_stage(OneShotResult& result) {
  const Eigen::VectorXd& X = reference_;
  const int n = options_.rigid_iterations;
  for (int it = 0; it < n; ++it) {
    const double gate = schedule(options_.start_gate, options_.end_gate, n > 1 ? static_cast<double>(it) / (n - 1) : 1.0);
    const std::vector<Match> matches = match(X, alignment_, gate);
    if (matches.size() < 6) break;
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (const Match& m : matches) c += alignment_ * points_[m.point].getVector3fMap().cast<double>();
    c /= matches.size();
    Eigen::Matrix<double, 6, 6> N = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
    for (const Match& m : matches) {
      const Eigen::Vector3d q = alignment_ * points_[m.point].getVector3fMap().cast<double>();
      const Eigen::Vector3d& normal = m.hit.normal;
      // The cloud moves by w x (q - c) + t: its distance along the normal by -J.(w, t).
      Eigen::Matrix<double, 6, 1> J;
      J << -(q - c).cross(normal), -normal;
      const double r = normal.dot(m.hit.point - q);
      N += m.weight * J * J.transpose();
      b -= m.weight * J * r;
    }
    const Eigen::Matrix<double, 6, 1> d = N.ldlt().solve(b);
    if (!d.allFinite()) break;
    alignment_ = rigid_step(c, d.head<3>(), d.tail<3>()) * alignment_;
    if (d.head<3>().norm() < 1e-7 && d.tail<3>().norm() < 1e-8 && it > 0) break;
  }
  double sum = 0;
  const std::vector<Match> matches = match(X, alignment_, options_.end_gate);
  for (const Match& m : matches) sum += m.hit.distance * m.hit.distance;
  result.rigid_rms = matches.empty() ? 0.0 : std::sqrt(sum / matches.size());
  result.rigid_alignment = alignment_;
}

void OneShotRegistration::settle(int iterations) {
  for (int i = 0; i < iterations; ++i) {
    compliance_.factorize();
    model_->set_positions(compliance_.equilibrium());
  }
}

void OneShotRegistration::deformation_stage(OneShotResult& result) {
  const Eigen::MatrixX3i& F = model_->boundary();
  const int m = static_cast<int>(unit_loads_.cols());
  const int steps = options_.rounds * options_.iterations;
  Eigen::MatrixXd B, J;
  Eigen::VectorXd r, w;
  for (int round = 0; round < options_.rounds; ++round) {
    compliance_.factorize();
    const Eigen::VectorXd y0 = compliance_.equilibrium();
    compliance_.solve(unit_loads_, B);
    Eigen::VectorXd dg = Eigen::VectorXd::Zero(m);
    for (int it = 0; it < options_.iterations; ++it) {
      const double t = steps > 1 ? static_cast<double>(round * options_.iterations + it) / (steps - 1) : 1.0;
      const double gate = schedule(options_.start_gate, options_.end_gate, t);
      const double damping = schedule(options_.start_damping, options_.load_damping, t);
      const Eigen::VectorXd y = y0 + B * dg;
      const std::vector<Match> matches = match(y, alignment_, gate);
      if (matches.size() < 6) break;
      const int rows = static_cast<int>(matches.size());
      J.resize(rows, m + 6);
      r.resize(rows);
      w.resize(rows);
      Eigen::Vector3d c = Eigen::Vector3d::Zero();
      for (const Match& mt : matches) c += alignment_ * points_[mt.point].getVector3fMap().cast<double>();
      c /= rows;
      for (int k = 0; k < rows; ++k) {
        const Match& mt = matches[k];
        const Eigen::Vector3d q = alignment_ * points_[mt.point].getVector3fMap().cast<double>();
        const Eigen::Vector3d& normal = mt.hit.normal;
        J.row(k).head(m).setZero();
        for (int j = 0; j < 3; ++j)
          J.row(k).head(m) += mt.hit.weights[j] * normal.transpose() * B.middleRows<3>(3 * F(mt.hit.triangle, j));
        J.row(k).segment<3>(m) = -(q - c).cross(normal).transpose();
        J.row(k).segment<3>(m + 3) = -normal.transpose();
        r[k] = normal.dot(mt.hit.point - q);
        w[k] = mt.weight;
      }
      const Eigen::MatrixXd Jw = w.cwiseSqrt().asDiagonal() * J;
      Eigen::MatrixXd N = Eigen::MatrixXd::Zero(m + 6, m + 6);
      N.selfadjointView<Eigen::Lower>().rankUpdate(Jw.transpose());
      const double lambda = damping * N.topLeftCorner(m, m).trace() / m;
      N.topLeftCorner(m, m).diagonal().array() += lambda;
      Eigen::VectorXd b = -Jw.transpose() * (w.cwiseSqrt().asDiagonal() * r);
      b.head(m) -= lambda * (loads_ + dg);
      const Eigen::VectorXd d = N.selfadjointView<Eigen::Lower>().ldlt().solve(b);
      if (!d.allFinite()) break;
      dg += d.head(m);
      alignment_ = rigid_step(c, d.segment<3>(m), d.segment<3>(m + 3)) * alignment_;
      if (round + 1 == options_.rounds && it + 1 == options_.iterations) {
        normal_ = N.selfadjointView<Eigen::Lower>();
        normal_.topLeftCorner(m, m).diagonal().array() -= lambda;  // the data's alone
        damping_ = lambda;
        centre_ = c;
      }
    }
    if (round + 1 == options_.rounds) basis_.swap(B);
    loads_ += dg;
    model_->set_surface_loads(reference_loads_ + unit_loads_ * loads_);
    settle(round + 1 < options_.rounds ? 1 : 2);
  }
  const Eigen::VectorXd& x = model_->positions();
  const std::vector<Match> matches = match(x, alignment_, options_.end_gate);
  std::vector<char> covered(F.rows(), 0);
  double sum = 0;
  for (const Match& mt : matches) {
    sum += mt.hit.distance * mt.hit.distance;
    covered[mt.hit.triangle] = 1;
  }
  double area = 0, covered_area = 0;
  for (int t = 0; t < F.rows(); ++t) {
    const double a = 0.5 * (node(x, F(t, 1)) - node(x, F(t, 0))).cross(node(x, F(t, 2)) - node(x, F(t, 0))).norm();
    area += a;
    if (covered[t]) covered_area += a;
  }
  result.correspondences = static_cast<int>(matches.size());
  if (result.correspondences < 50)
    throw std::invalid_argument(std::to_string(result.correspondences) +
                                " points correspond to the registered surface: at least 50 are needed");
  result.rms = std::sqrt(sum / matches.size());
  double weighted = 0, weights = 0;
  for (const Match& mt : matches) weighted += mt.weight * mt.hit.distance * mt.hit.distance, weights += mt.weight;
  residual_variance_ = weighted / weights;
  result.coverage = covered_area / area;
  result.alignment = alignment_;
  result.positions = x;
  result.patch_loads.resize(patches_.centres.size());
  for (size_t p = 0; p < patches_.centres.size(); ++p) {
    result.patch_loads[p] = loads_.segment<3>(3 * p);
    result.load_total += result.patch_loads[p].norm();
  }
}

std::vector<OneShotRegistration::PointUncertainty> OneShotRegistration::uncertainty(
    const std::vector<EmbeddedPoint>& points) const {
  std::vector<PointUncertainty> out;
  if (basis_.size() == 0 || normal_.size() == 0) return out;
  const int m = static_cast<int>(basis_.cols());
  Eigen::MatrixXd damped = normal_;
  damped.topLeftCorner(m, m).diagonal().array() += damping_;
  const Eigen::LDLT<Eigen::MatrixXd> damped_ldlt(damped);
  // The loads' prior: independent, of the variance the fitted ones show (empirical Bayes), over
  // the loads the cloud determines (the effective number of parameters, m - lambda tr((N +
  // lambda)^-1) on the loads): the patches out of view keep loads near zero by the damping and
  // say nothing of the loads' size, so dividing by every patch would shrink the prior the more,
  // the less of the surface is seen.
  const Eigen::MatrixXd inverse = damped_ldlt.solve(Eigen::MatrixXd::Identity(m + 6, m + 6));
  const double determined = std::max(m - damping_ * inverse.topLeftCorner(m, m).trace(), 1.0);
  const double prior_variance = std::max(loads_.squaredNorm() / determined, 1e-300);
  Eigen::MatrixXd information = normal_ / residual_variance_;
  information.topLeftCorner(m, m).diagonal().array() += 1 / prior_variance;
  const Eigen::MatrixXd posterior = options_.posterior_scale * options_.posterior_scale *
                                    information.ldlt().solve(Eigen::MatrixXd::Identity(m + 6, m + 6));
  const Eigen::Matrix3d back = alignment_.linear().transpose();
  const Eigen::MatrixX4i& T = model_->mesh().T;
  const Eigen::VectorXd& x = model_->positions();
  const Eigen::VectorXd& X = reference_;
  // How the fit moves per unit log of the damping (at its optimum, the gradient zero):
  // dz/d ln lambda = -(N + lambda D)^-1 lambda D z.
  Eigen::VectorXd shift = Eigen::VectorXd::Zero(m + 6);
  shift.head(m) = -damping_ * loads_;
  shift = damped_ldlt.solve(shift);
  Eigen::MatrixXd J(3, m + 6);
  for (const EmbeddedPoint& e : points) {
    PointUncertainty u;
    const Eigen::Vector3d p = interpolate(T, x, e);
    u.position = alignment_.inverse() * p;
    u.displacement = p - interpolate(T, X, e);
    J.setZero();
    for (int k = 0; k < 4; ++k) J.leftCols(m) += e.barycentric[k] * basis_.middleRows<3>(3 * T(e.tet, k));
    // The cloud moved by w x (q - c) + t moves a model point, seen from the cloud, by
    // -(w x (p - c) + t): (p - c) x w - t.
    const Eigen::Vector3d a = p - centre_;
    Eigen::Matrix3d cross;
    cross << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
    J.middleCols<3>(m) = cross;
    J.middleCols<3>(m + 3) = -Eigen::Matrix3d::Identity();
    const Eigen::MatrixXd seen = back * J;
    u.fit = seen * posterior * seen.transpose();
    u.prior = seen * shift;
    const double floor = options_.model_error_floor, bias = options_.damping_error * u.prior.norm(),
                 form = options_.displacement_error * u.displacement.norm();
    u.model = (floor * floor + bias * bias + form * form) * Eigen::Matrix3d::Identity();
    out.push_back(u);
  }
  return out;
}

}  // namespace liver_sim
