#include "liver_sim/liver_model.h"

#include "liver_sim/contact_solver.h"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <omp.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace liver_sim {
namespace {

using Clock = std::chrono::steady_clock;
constexpr int kMaxKrylov = 30;      // GMRES iterations per Newton step
constexpr int kRefactorAfter = 10;  // GMRES iterations beyond which the factor is refreshed
constexpr int kMaxStages = 16;      // instrument stages per step
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

void require_valid(const std::string& message) {
  if (!message.empty()) throw std::invalid_argument(message);
}

TetMesh validated(TetMesh mesh) {
  validate_mesh(mesh, "mesh");
  return mesh;
}

const Scene& validated(const Scene& scene) {
  require_valid(validate(scene.parenchyma));
  require_valid(validate(scene.capsule));
  require_valid(validate(scene.solver));
  require_valid(validate(scene.contact));
  return scene;
}

Eigen::VectorXd flatten(const Eigen::MatrixX3d& V) {
  Eigen::VectorXd x(3 * V.rows());
  for (int i = 0; i < V.rows(); ++i) x.segment<3>(3 * i) = V.row(i).transpose();
  return x;
}

double free_norm(const Eigen::VectorXd& r, const std::vector<char>& fixed) {
  double s = 0;
  for (int i = 0; i < r.size(); ++i)
    if (!fixed[i]) s += r[i] * r[i];
  return std::sqrt(s);
}

}  // namespace

TetMesh load_scene_mesh(const Scene& scene) {
  if (scene.mesh.file.empty()) return make_box_mesh(scene.mesh.box_size, scene.mesh.box_divisions);
  return read_mesh(scene.mesh.file, scene.mesh.scale);
}

LiverModel::LiverModel(TetMesh mesh, const Scene& scene)
    : mesh_(validated(std::move(mesh))),
      boundary_(boundary_triangles(mesh_.T)),
      solver_(validated(scene).solver),
      parenchyma_(scene.parenchyma),
      capsule_(scene.capsule),
      tetra_(mesh_.V, mesh_.T, parenchyma_),
      membrane_(mesh_.V, boundary_, capsule_),
      contact_(scene.contact) {
  const int n = static_cast<int>(mesh_.V.rows());
  const std::vector<std::vector<int>> beam_groups = embed_vessels(scene.vessels);
  const int dofs = 3 * n;
  pattern_ = SparsePattern(n, mesh_.T, beam_groups);
  on_boundary_.assign(n, 0);
  for (int f = 0; f < boundary_.rows(); ++f)
    for (int k = 0; k < 3; ++k) on_boundary_[boundary_(f, k)] = 1;

  tet_map_.reserve(144 * mesh_.T.rows());
  for (int e = 0; e < mesh_.T.rows(); ++e) {
    const int nodes[4] = {mesh_.T(e, 0), mesh_.T(e, 1), mesh_.T(e, 2), mesh_.T(e, 3)};
    pattern_.append_scatter_map(nodes, 4, tet_map_);
  }
  tri_map_.reserve(81 * boundary_.rows());
  for (int f = 0; f < boundary_.rows(); ++f) {
    const int nodes[3] = {boundary_(f, 0), boundary_(f, 1), boundary_(f, 2)};
    pattern_.append_scatter_map(nodes, 3, tri_map_);
  }
  beam_map_.reserve(576 * beam_groups.size());
  for (const std::vector<int>& g : beam_groups) pattern_.append_scatter_map(g.data(), 8, beam_map_);
  stiffness_.assign(pattern_.nonzeros(), 0.0);
  threads_ = std::max(1, omp_get_max_threads());
  thread_forces_.resize(threads_);
  thread_energy_.assign(threads_, 0.0);
  thread_stiffness_.assign(threads_, std::vector<double>());
  for (int t = 1; t < threads_; ++t) {
    thread_forces_[t].setZero(dofs);
    thread_stiffness_[t].assign(pattern_.nonzeros(), 0.0);
  }
  system_.assign(pattern_.nonzeros(), 0.0);
  solver_cholmod_.analyze(pattern_.rows(), pattern_.column_start(), pattern_.row_index());

  X_ = flatten(mesh_.V);
  x_ = X_;
  v_ = Eigen::VectorXd::Zero(dofs);
  v_previous_ = v_;
  x_start_ = X_;
  x_stage_ = X_;
  mass_ = Eigen::VectorXd::Zero(dofs);
  for (int e = 0; e < mesh_.T.rows(); ++e)
    for (int k = 0; k < 4; ++k)
      mass_.segment<3>(3 * mesh_.T(e, k)).array() += parenchyma_.density * tetra_.volume(e) / 4;

  const Eigen::Vector3d extent = mesh_.V.colwise().maxCoeff() - mesh_.V.colwise().minCoeff();
  length_scale_ = extent.norm();
  force_floor_ = 1e-12 * parenchyma_.young_modulus * extent.squaredNorm();

  require_valid(set_capsule(capsule_));

  std::vector<int> fixed_nodes;
  for (size_t i = 0; i < scene.fixed.size(); ++i) {
    const std::vector<int> s = select_nodes(scene.fixed[i], "fixed." + std::to_string(i));
    fixed_nodes.insert(fixed_nodes.end(), s.begin(), s.end());
  }
  if (fixed_nodes.empty() && solver_.mode == SolverOptions::Mode::Static)
    throw std::invalid_argument("fixed: a static scene needs fixed nodes (the stiffness matrix is singular otherwise)");
  scene_fixed_nodes_ = fixed_nodes;
  fixed_by_scene_.assign(n, 0);
  for (int i : fixed_nodes) fixed_by_scene_[i] = 1;
  set_fixed(fixed_nodes);
  for (int i = 0; i < n; ++i)
    if (on_boundary_[i]) boundary_nodes_.push_back(i);

  for (size_t i = 0; i < scene.loads.size(); ++i) {
    const LoadOptions& load = scene.loads[i];
    const std::string what = "loads." + std::to_string(i);
    switch (load.kind) {
      case LoadOptions::Kind::Pressure: {
        if (!std::isfinite(load.pressure)) throw std::invalid_argument(what + ".value must be finite");
        PressureLoad p{load.pressure, {}};
        if (load.region) {
          p.triangles = select_triangles(*load.region, what + ".region");
        } else {
          p.triangles.resize(boundary_.rows());
          for (int f = 0; f < boundary_.rows(); ++f) p.triangles[f] = f;
        }
        pressures_.push_back(std::move(p));
        break;
      }
      case LoadOptions::Kind::Gravity: {
        if (!load.vector.allFinite()) throw std::invalid_argument(what + ".acceleration must be finite");
        gravity_ += load.vector;
        break;
      }
      case LoadOptions::Kind::Force: {
        if (!load.vector.allFinite()) throw std::invalid_argument(what + ".total must be finite");
        if (!load.region) throw std::invalid_argument(what + ".region is required for a force");
        std::vector<int> nodes = select_nodes(*load.region, what + ".region");
        nodal_loads_.push_back({load.vector / static_cast<double>(nodes.size()), std::move(nodes)});
        break;
      }
    }
  }

  for (const ProbeOptions& p : scene.probes) {
    if (!p.point.allFinite()) throw std::invalid_argument("probe '" + p.name + "': point must be finite");
    const EmbeddedPoint at = locate(p.point);
    // Points on a curved surface may sit a little outside the faceted mesh.
    if (at.barycentric.minCoeff() < -0.05) throw std::invalid_argument("probe '" + p.name + "' lies outside the mesh");
    probes_.push_back({p.name, at});
  }

  for (Eigen::VectorXd* v : {&r_, &r_try_, &dx_, &x_try_, &f_tmp_, &v_tmp_, &f_ext_, &energy_work_,
                             &contact_force_, &contact_force_start_})
    v->setZero(dofs);
  compliance_slot_.assign(n, -1);
  for (const InstrumentOptions& o : scene.instruments) add_instrument(o);
  snapshot_damping();  // so that any residual before the first step finds one
}

LiverModel::EmbeddedPoint LiverModel::locate(const Eigen::Vector3d& p) const {
  EmbeddedPoint best;
  double best_min = -std::numeric_limits<double>::infinity();
  for (int e = 0; e < mesh_.T.rows(); ++e) {
    const Eigen::Vector3d w = tetra_.rest_edge_inverse(e) * (p - mesh_.V.row(mesh_.T(e, 0)).transpose());
    const Eigen::Vector4d b(1 - w.sum(), w[0], w[1], w[2]);
    if (b.minCoeff() > best_min) {
      best_min = b.minCoeff();
      best = {e, b};
    }
  }
  return best;
}

Eigen::Vector3d LiverModel::interpolate(const Eigen::VectorXd& x, const EmbeddedPoint& q) const {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) p += q.barycentric[k] * x.segment<3>(3 * mesh_.T(q.tet, k));
  return p;
}

std::vector<std::vector<int>> LiverModel::embed_vessels(const std::vector<VesselOptions>& vessels) {
  const Eigen::VectorXd rest_x = flatten(mesh_.V);
  std::vector<Eigen::Vector3d> rest;
  std::vector<Eigen::Vector2i> segments;
  std::vector<BeamSection> sections;
  for (const VesselOptions& v : vessels) {
    require_valid(validate(v));
    if (!v.enabled) continue;
    const std::string what = "vessels." + v.name;
    VesselTree tree;
    try {
      tree = read_vessel_tree(v.file, v.scale);
    } catch (const VesselError& e) {
      throw std::invalid_argument(what + ": " + e.what());
    }
    const int base = num_vessel_nodes();
    for (int i = 0; i < tree.points.rows(); ++i) {
      const Eigen::Vector3d p = tree.points.row(i).transpose();
      EmbeddedPoint at = locate(p);
      if (at.barycentric.minCoeff() < 0) {
        // Outside the faceted surface: onto the nearest point of the best tetrahedron's span
        // (clamped weights), if that is within the tolerance.
        at.barycentric = at.barycentric.cwiseMax(0.0);
        at.barycentric /= at.barycentric.sum();
        const double gap = (interpolate(rest_x, at) - p).norm();
        if (gap > v.snap_tolerance) {
          std::ostringstream m;
          m << what << ": node " << i << " at (" << p.transpose() << ") m lies " << gap * 1e3
            << " mm outside the mesh (snap_tolerance " << v.snap_tolerance * 1e3 << " mm)";
          throw std::invalid_argument(m.str());
        }
      }
      vessel_nodes_.push_back(at);
      rest.push_back(interpolate(rest_x, at));
    }
    for (int s = 0; s < tree.segments.rows(); ++s) {
      const int a = tree.segments(s, 0), b = tree.segments(s, 1);
      segments.emplace_back(base + a, base + b);
      BeamSection section;
      section.outer_radius = 0.5 * (tree.radius[a] + tree.radius[b]);
      section.wall_thickness = 0.5 * (tree.wall_thickness[a] + tree.wall_thickness[b]);
      section.young_modulus = v.young_modulus;
      section.poisson_ratio = v.poisson_ratio;
      sections.push_back(section);
      beam_vessel_.push_back(static_cast<int>(vessel_names_.size()));
    }
    vessel_names_.push_back(v.name);
  }
  std::vector<std::vector<int>> groups;  // per beam, the 4 nodes of each end's tetrahedron
  if (segments.empty()) return groups;
  const int m = num_vessel_nodes();
  Eigen::MatrixX3d X(m, 3);
  for (int k = 0; k < m; ++k) X.row(k) = rest[k].transpose();
  Eigen::MatrixX2i S(static_cast<int>(segments.size()), 2);
  for (size_t s = 0; s < segments.size(); ++s) S.row(s) = segments[s].transpose();
  beams_.emplace(X, S, sections);
  host_index_.assign(mesh_.T.rows(), -1);
  for (const EmbeddedPoint& p : vessel_nodes_) {
    if (host_index_[p.tet] >= 0) continue;
    host_index_[p.tet] = static_cast<int>(hosts_.size());
    hosts_.push_back(p.tet);
  }
  host_rotation_.assign(hosts_.size(), Eigen::Matrix3d::Identity());
  host_rotation_derivative_.assign(hosts_.size(), Eigen::Matrix<double, 3, 12>::Zero());
  vessel_rotation_.assign(m, Eigen::Matrix3d::Identity());
  vessel_positions_.setZero(3 * m);
  for (int e = 0; e < beams_->size(); ++e) {
    std::vector<int> g;
    for (int end = 0; end < 2; ++end)
      for (int k = 0; k < 4; ++k) g.push_back(mesh_.T(vessel_nodes_[S(e, end)].tet, k));
    groups.push_back(std::move(g));
  }
  return groups;
}

std::vector<int> LiverModel::select_nodes(const Region& r, const std::string& what) const {
  require_valid(validate(r));
  std::vector<int> nodes;
  for (int i = 0; i < mesh_.V.rows(); ++i)
    if ((!r.boundary_only() || on_boundary_[i]) && r.contains(mesh_.V.row(i).transpose()))
      nodes.push_back(i);
  if (nodes.empty()) throw std::invalid_argument(what + ": the region selects no node");
  return nodes;
}

std::vector<int> LiverModel::select_triangles(const Region& r, const std::string& what) const {
  require_valid(validate(r));
  std::vector<int> triangles;
  for (int f = 0; f < boundary_.rows(); ++f) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) c += mesh_.V.row(boundary_(f, k)).transpose() / 3.0;
    if (r.contains(c)) triangles.push_back(f);
  }
  if (triangles.empty()) throw std::invalid_argument(what + ": the region selects no boundary triangle");
  return triangles;
}

void LiverModel::set_fixed(const std::vector<int>& nodes) {
  fixed_next_.assign(X_.size(), 0);
  for (int node : nodes)
    for (int c = 0; c < 3; ++c) fixed_next_[3 * node + c] = 1;
  if (fixed_next_ == fixed_dof_) return;  // same constraints: the factor stays valid
  fixed_dof_.swap(fixed_next_);
  factor_valid_ = false;
  fixed_entries_.clear();
  const auto& start = pattern_.column_start();
  const auto& rows = pattern_.row_index();
  for (int col = 0; col < pattern_.rows(); ++col)
    for (int k = start[col]; k < start[col + 1]; ++k)
      if (rows[k] != col && (fixed_dof_[col] || fixed_dof_[rows[k]])) fixed_entries_.push_back(k);
}

std::string LiverModel::set_capsule(const CapsuleOptions& capsule) {
  const std::string error = validate(capsule);
  if (!error.empty()) return error;
  std::vector<int> active;
  if (capsule.region) {
    try {
      active = select_triangles(*capsule.region, "capsule.region");
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
  } else {
    active.resize(boundary_.rows());
    for (int f = 0; f < boundary_.rows(); ++f) active[f] = f;
  }
  membrane_.set_material(capsule);
  state_energy_ = std::numeric_limits<double>::quiet_NaN();
  rotations_at_.resize(0);  // the membrane rotations may not follow the last evaluation
  capsule_active_ = std::move(active);
  capsule_ = capsule;
  factor_valid_ = false;
  // The membranes' frames for the damping, should a residual be evaluated before the next step
  // (the constructor takes its own snapshot once it is complete).
  if (!damping_.tet_rotation.empty()) snapshot_damping();
  return "";
}

std::string LiverModel::set_solver_options(const SolverOptions& solver) {
  const std::string error = validate(solver);
  if (!error.empty()) return error;
  if (solver.mode != solver_.mode) return "solver.mode cannot change on a running model";
  // The factored matrix depends on dt and the damping (dynamic mode); the strategy and the
  // iteration controls leave it valid.
  if (solver.dt != solver_.dt || solver.rayleigh_mass != solver_.rayleigh_mass ||
      solver.rayleigh_stiffness != solver_.rayleigh_stiffness)
    factor_valid_ = false;
  // The predictor's acceleration and the rotations' angular velocity are differences over one
  // step: a new dt starts them afresh.
  if (solver.dt != solver_.dt) {
    v_previous_ = v_;
    rotations_continued_ = false;
  }
  solver_ = solver;
  return "";
}

int LiverModel::capsule_triangles() const {
  return capsule_.enabled ? static_cast<int>(capsule_active_.size()) : 0;
}

void LiverModel::reset() {
  factor_valid_ = false;
  tetra_.reset_rotations();
  rotations_at_.resize(0);
  state_energy_ = std::numeric_limits<double>::quiet_NaN();
  x_ = X_;
  contacts_.clear();
  contact_force_.setZero();
  for (Instrument& in : instruments_) {
    in.closed = false;
    in.was_enabled = false;
    in.held.clear();
    in.held_local.clear();
    in.reaction = InstrumentReaction{};
  }
  v_.setZero();
  v_previous_.setZero();
  rotations_continued_ = false;
  x_start_ = X_;
  time_ = 0;
  surface_targets_.clear();
}

double LiverModel::max_displacement() const {
  double max_u = 0;
  for (int i = 0; i < x_.size(); i += 3) max_u = std::max(max_u, (x_.segment<3>(i) - X_.segment<3>(i)).norm());
  return max_u;
}

Eigen::Vector3d LiverModel::probe_displacement(int i) const {
  return interpolate(x_, probes_[i].at) - interpolate(X_, probes_[i].at);
}

void LiverModel::internal_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) {
  // The last evaluation is kept: a step starts where the previous one ended, and the energy
  // check looks at the state the line search accepted.
  if (rotations_at_.size() == x.size() && rotations_at_ == x) {
    f = internal_at_;
    return;
  }
  f.setZero(x.size());
  if (capsule_.enabled) membrane_.update_rotations(x);  // the tetrahedra's rotations come with their forces
  // Elements split over the cores, each thread adding into its own force vector (thread 0
  // into f); the vectors are summed in a fixed order, so a result depends only on the thread count.
  const int active = static_cast<int>(capsule_active_.size());
#pragma omp parallel num_threads(threads_)
  {
    const int thread = omp_get_thread_num();
    Eigen::VectorXd& ft = thread == 0 ? f : thread_forces_[thread];
    if (thread > 0) ft.setZero(x.size());
    double energy = 0;  // the strain energy comes with the forces, at little extra cost
    Vector12d fe[4];
    const int tetrahedra = tetra_.size();
#pragma omp for schedule(static) nowait
    for (int block = 0; block < (tetrahedra + 3) / 4; ++block) {  // four at a time: see polar_rotations
      const int first = 4 * block, count = std::min(4, tetrahedra - first);
      energy += tetra_.element_forces(first, count, x, fe);
      for (int i = 0; i < count; ++i)
        for (int k = 0; k < 4; ++k) ft.segment<3>(3 * mesh_.T(first + i, k)) += fe[i].segment<3>(3 * k);
    }
    if (capsule_.enabled) {
      Vector9d fm;
#pragma omp for schedule(static) nowait
      for (int i = 0; i < active; ++i) {
        const int t = capsule_active_[i];
        energy += membrane_.element_force(t, x, fm);
        for (int k = 0; k < 3; ++k) ft.segment<3>(3 * boundary_(t, k)) += fm.segment<3>(3 * k);
      }
    }
    thread_energy_[thread] = energy;
  }
  tissue_energy_at_ = thread_energy_[0];
  for (int thread = 1; thread < threads_; ++thread) {
    f += thread_forces_[thread];
    tissue_energy_at_ += thread_energy_[thread];
  }
  if (beams_) add_beam_forces(x, f);
  rotations_at_ = x;
  internal_at_ = f;
}

void LiverModel::add_beam_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) {
  for (size_t h = 0; h < hosts_.size(); ++h) {
    const Eigen::Matrix3d F = tetra_.deformation_gradient(hosts_[h], x);
    // The vessel follows the polar rotation of its host; with polar parenchyma that is the
    // rotation the tetrahedron's force has just computed at x.
    host_rotation_[h] = parenchyma_.rotation == RotationMethod::Polar ? tetra_.rotation(hosts_[h]) : polar_rotation(F);
    host_rotation_derivative_[h] = polar_rotation_derivative(host_rotation_[h], F, tetra_.rest_edge_inverse(hosts_[h]));
  }
  for (int k = 0; k < num_vessel_nodes(); ++k) {
    vessel_positions_.segment<3>(3 * k) = interpolate(x, vessel_nodes_[k]);
    vessel_rotation_[k] = host_rotation_[host_index_[vessel_nodes_[k].tet]];
  }
  beams_->update_frames(vessel_positions_, vessel_rotation_);
  Vector12d fe;
  for (int e = 0; e < beams_->size(); ++e) {
    beams_->element_force(e, fe);
    for (int end = 0; end < 2; ++end) {
      const EmbeddedPoint& at = vessel_nodes_[beams_->segments()(e, end)];
      // Force through the barycentric weights, moment through d theta / d x of the host.
      const Eigen::Matrix<double, 3, 12>& G = host_rotation_derivative_[host_index_[at.tet]];
      const Eigen::Matrix<double, 12, 1> fm = G.transpose() * fe.segment<3>(6 * end + 3);
      for (int k = 0; k < 4; ++k)
        f.segment<3>(3 * mesh_.T(at.tet, k)) += at.barycentric[k] * fe.segment<3>(6 * end) + fm.segment<3>(3 * k);
    }
  }
}

Eigen::Matrix<double, 12, 24> LiverModel::beam_mapping(int e) const {
  Eigen::Matrix<double, 12, 24> J = Eigen::Matrix<double, 12, 24>::Zero();
  for (int end = 0; end < 2; ++end) {
    const EmbeddedPoint& at = vessel_nodes_[beams_->segments()(e, end)];
    for (int k = 0; k < 4; ++k) J.block<3, 3>(6 * end, 3 * (4 * end + k)).diagonal().setConstant(at.barycentric[k]);
    J.block<3, 12>(6 * end + 3, 12 * end) = host_rotation_derivative_[host_index_[at.tet]];
  }
  return J;
}

double LiverModel::elastic_energy(const Eigen::VectorXd& x) {
  internal_forces(x, energy_work_);  // brings every rotation and beam frame to x (often already there)
  double energy = tissue_energy_at_;
  for (int e = 0; e < num_beams(); ++e) energy += beams_->element_energy(e);
  return energy;
}

double LiverModel::mechanical_energy(const Eigen::VectorXd& x, const Eigen::VectorXd& v) {
  return 0.5 * v.dot(mass_.cwiseProduct(v)) + elastic_energy(x);
}

double LiverModel::work_over_step() {
  // Loads: trapezoid rule between the start and the end of the step. Instruments: their force
  // at the end of the step times the displacement (they move only the nodes they touch).
  external_forces(x_start_, f_ext_);
  external_forces(x_, energy_work_);
  f_ext_ = 0.5 * load_scale_ * (f_ext_ + energy_work_) + contact_force_;
  if (!surface_targets_.empty()) {
    energy_work_.setZero();
    add_target_forces(x_start_, energy_work_);
    add_target_forces(x_, energy_work_);
    f_ext_ += 0.5 * energy_work_;
  }
  double work = 0;
  for (int i = 0; i < x_.size(); ++i)
    if (!fixed_dof_[i]) work += (x_[i] - x_start_[i]) * f_ext_[i];
  return work;
}

void LiverModel::external_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const {
  f.setZero(x.size());
  for (const PressureLoad& p : pressures_) {
    for (int t : p.triangles) {
      const int a = boundary_(t, 0), b = boundary_(t, 1), c = boundary_(t, 2);
      // Follower load: -p times the current outward area vector, a third to each node.
      const Eigen::Vector3d area = 0.5 * (x.segment<3>(3 * b) - x.segment<3>(3 * a))
                                             .cross(x.segment<3>(3 * c) - x.segment<3>(3 * a));
      const Eigen::Vector3d fn = -p.pressure * area / 3.0;
      f.segment<3>(3 * a) += fn;
      f.segment<3>(3 * b) += fn;
      f.segment<3>(3 * c) += fn;
    }
  }
  for (const NodalLoad& l : nodal_loads_)
    for (int node : l.nodes) f.segment<3>(3 * node) += l.force;
  if (!gravity_.isZero())
    for (int i = 0; i < f.size(); i += 3) f.segment<3>(i) += mass_[i] * gravity_;
}

void LiverModel::set_surface_targets(std::vector<SurfaceTarget> targets) {
  for (size_t i = 0; i < targets.size(); ++i) {
    const SurfaceTarget& t = targets[i];
    const std::string which = "surface target " + std::to_string(i);
    if (t.triangle < 0 || t.triangle >= boundary_.rows())
      throw std::invalid_argument(which + ": triangle " + std::to_string(t.triangle) + " is not a boundary triangle");
    if (!t.weights.allFinite() || !t.point.allFinite() || !t.normal.allFinite() || !std::isfinite(t.stiffness) ||
        t.stiffness < 0)
      throw std::invalid_argument(which + ": weights, point, normal and stiffness must be finite, stiffness >= 0");
    if (!t.normal.isZero(0.0) && std::abs(t.normal.norm() - 1) > 1e-9)
      throw std::invalid_argument(which + ": the normal must be a unit vector or zero");
  }
  // A factor without springs (or with far weaker ones) preconditions badly; frame-to-frame
  // changes of the same cloud's springs keep it.
  double total = 0, before = 0;
  for (const SurfaceTarget& t : targets) total += t.stiffness;
  for (const SurfaceTarget& t : surface_targets_) before += t.stiffness;
  if (std::abs(total - before) > 0.5 * std::max(total, before)) factor_valid_ = false;
  surface_targets_ = std::move(targets);
  state_energy_ = std::numeric_limits<double>::quiet_NaN();
}

void LiverModel::add_target_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const {
  for (const SurfaceTarget& t : surface_targets_) {
    Eigen::Vector3d on_surface = -t.point;
    for (int j = 0; j < 3; ++j) on_surface += t.weights[j] * x.segment<3>(3 * boundary_(t.triangle, j));
    const Eigen::Vector3d pull =
        -t.stiffness * (t.normal.isZero(0.0) ? on_surface : Eigen::Vector3d(t.normal * t.normal.dot(on_surface)));
    for (int j = 0; j < 3; ++j) f.segment<3>(3 * boundary_(t.triangle, j)) += t.weights[j] * pull;
  }
}

double LiverModel::residual(const Eigen::VectorXd& x, Eigen::VectorXd& r, double* reference, bool zero_fixed) {
  internal_forces(x, f_tmp_);
  external_forces(x, r);
  r *= load_scale_;
  add_target_forces(x, r);
  const double load_norm = free_norm(r, fixed_dof_);
  // All DOFs: under prescribed displacements alone the reactions are the force scale.
  const double internal_norm = f_tmp_.norm();
  r -= f_tmp_;
  if (!contacts_.empty()) r += contact_force_;
  if (solver_.mode == SolverOptions::Mode::Dynamic) {
    const double dt = solver_.dt;
    // Backward Euler: M (v - v_n)/dt + D v = f_ext - f_int, v = (x - x_n)/dt, D = a M + b K.
    v_tmp_ = (x - x_start_) / dt;
    r -= mass_.cwiseProduct((v_tmp_ - v_) / dt + solver_.rayleigh_mass * v_tmp_);
    if (solver_.rayleigh_stiffness > 0 && !v_tmp_.isZero(0.0)) {  // v = 0: at rest, or before any step
      damping_forces(v_tmp_, f_tmp_);
      r -= solver_.rayleigh_stiffness * f_tmp_;
    }
  }
  for (int i = 0; zero_fixed && i < r.size(); ++i)
    if (fixed_dof_[i]) r[i] = 0;
  *reference = std::max({load_norm, internal_norm, force_floor_});
  return r.norm();
}

void LiverModel::snapshot_damping() {
  internal_forces(x_start_, f_tmp_);  // brings rotations, frames and hosts to x_start_ (usually already there)
  damping_.tet_rotation = tetra_.rotations();
  if (capsule_.enabled) damping_.membrane_frame = membrane_.frames();
  damping_.beam_tangent.resize(num_beams());
  damping_.beam_mapping.resize(num_beams());
  for (int e = 0; e < num_beams(); ++e) {
    beams_->element_tangent(e, damping_.beam_tangent[e]);
    damping_.beam_mapping[e] = beam_mapping(e);
  }
}

void LiverModel::damping_forces(const Eigen::VectorXd& v, Eigen::VectorXd& f) {
  f.setZero(v.size());
  const int active = static_cast<int>(capsule_active_.size());
#pragma omp parallel num_threads(threads_)
  {  // as internal_forces: per-thread vectors summed in a fixed order
    const int thread = omp_get_thread_num();
    Eigen::VectorXd& ft = thread == 0 ? f : thread_forces_[thread];
    if (thread > 0) ft.setZero(v.size());
    Vector12d fe[4];
    const int tetrahedra = tetra_.size();
#pragma omp for schedule(static) nowait
    for (int block = 0; block < (tetrahedra + 3) / 4; ++block) {
      const int first = 4 * block, count = std::min(4, tetrahedra - first);
      tetra_.tangent_products(first, count, damping_.tet_rotation, v, fe);
      for (int i = 0; i < count; ++i)
        for (int k = 0; k < 4; ++k) ft.segment<3>(3 * mesh_.T(first + i, k)) += fe[i].segment<3>(3 * k);
    }
    if (capsule_.enabled) {
      Vector9d fm;
#pragma omp for schedule(static) nowait
      for (int i = 0; i < active; ++i) {
        const int t = capsule_active_[i];
        membrane_.tangent_product(t, damping_.membrane_frame[t], v, fm);
        for (int k = 0; k < 3; ++k) ft.segment<3>(3 * boundary_(t, k)) += fm.segment<3>(3 * k);
      }
    }
  }
  for (int thread = 1; thread < threads_; ++thread) f += thread_forces_[thread];
  for (int e = 0; e < num_beams(); ++e) {
    Eigen::Matrix<double, 24, 1> ve;
    for (int end = 0; end < 2; ++end) {
      const int tet = vessel_nodes_[beams_->segments()(e, end)].tet;
      for (int k = 0; k < 4; ++k) ve.segment<3>(12 * end + 3 * k) = v.segment<3>(3 * mesh_.T(tet, k));
    }
    const Eigen::Matrix<double, 12, 24>& J = damping_.beam_mapping[e];
    const Eigen::Matrix<double, 24, 1> fe = J.transpose() * (damping_.beam_tangent[e] * (J * ve));
    for (int end = 0; end < 2; ++end) {
      const int tet = vessel_nodes_[beams_->segments()(e, end)].tet;
      for (int k = 0; k < 4; ++k) f.segment<3>(3 * mesh_.T(tet, k)) += fe.segment<3>(12 * end + 3 * k);
    }
  }
}

void LiverModel::assemble_system() {
  const int active = static_cast<int>(capsule_active_.size());
#pragma omp parallel num_threads(threads_)
  {  // as internal_forces: one matrix value array per thread, summed in order
    const int thread = omp_get_thread_num();
    std::vector<double>& kt = thread == 0 ? stiffness_ : thread_stiffness_[thread];
    std::fill(kt.begin(), kt.end(), 0.0);
    Matrix12d Ke;
#pragma omp for schedule(static) nowait
    for (int e = 0; e < tetra_.size(); ++e) {
      tetra_.element_tangent(e, Ke);
      scatter_add(Ke, &tet_map_[144 * e], kt);
    }
    if (capsule_.enabled) {
      Matrix9d Km;
#pragma omp for schedule(static) nowait
      for (int i = 0; i < active; ++i) {
        const int t = capsule_active_[i];
        membrane_.element_tangent(t, Km);
        scatter_add(Km, &tri_map_[81 * t], kt);
      }
    }
  }
  for (int thread = 1; thread < threads_; ++thread)
    for (size_t k = 0; k < stiffness_.size(); ++k) stiffness_[k] += thread_stiffness_[thread][k];
  Matrix12d Ke;
  for (int e = 0; e < num_beams(); ++e) {
    beams_->element_tangent(e, Ke);
    const Eigen::Matrix<double, 12, 24> J = beam_mapping(e);
    const Eigen::Matrix<double, 24, 24> Kb = J.transpose() * Ke * J;
    scatter_add(Kb, &beam_map_[576 * e], stiffness_);
  }
  // Static: A = K. Dynamic: A = (1 + b/dt) K + (1/dt^2 + a/dt) M.
  double k_scale = 1.0, m_scale = 0.0;
  if (solver_.mode == SolverOptions::Mode::Dynamic) {
    const double dt = solver_.dt;
    k_scale = 1.0 + solver_.rayleigh_stiffness / dt;
    m_scale = 1.0 / (dt * dt) + solver_.rayleigh_mass / dt;
  }
  for (size_t k = 0; k < stiffness_.size(); ++k) system_[k] = k_scale * stiffness_[k];
  // The targets' springs: external, so undamped; k w w^T (x) P per triangle, P = n n^T
  // (point-to-plane) or I.
  Matrix9d Kt;
  for (const SurfaceTarget& t : surface_targets_) {
    const Eigen::Matrix3d ww = t.stiffness * t.weights * t.weights.transpose();
    const Eigen::Matrix3d P =
        t.normal.isZero(0.0) ? Eigen::Matrix3d::Identity() : Eigen::Matrix3d(t.normal * t.normal.transpose());
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) Kt.block<3, 3>(3 * a, 3 * b) = ww(a, b) * P;
    scatter_add(Kt, &tri_map_[81 * t.triangle], system_);
  }
  for (int i = 0; i < pattern_.rows(); ++i) {
    system_[pattern_.diagonal(i)] += m_scale * mass_[i];
    if (fixed_dof_[i]) system_[pattern_.diagonal(i)] = 1.0;
  }
  for (int k : fixed_entries_) system_[k] = 0.0;
}

StepResult LiverModel::step() {
  const auto t_step = Clock::now();
  StepResult result;
  x_start_ = x_;  // the last good state, restored if the step diverges
  contact_force_start_ = contact_force_;
  const bool dynamic = solver_.mode == SolverOptions::Mode::Dynamic;
  if (dynamic && solver_.rayleigh_stiffness > 0) {
    // Rayleigh damping b K v with the stiffness of the state the step starts from, fixed within
    // the step so that the residual stays one function of x while Newton iterates; applied
    // element by element, not assembled (an assembly per step cost a third of a haptic frame).
    const auto t0 = Clock::now();
    snapshot_damping();
    result.timing.assembly_ms += ms_since(t0);
  }
  // An instrument that moves more than a quarter of its size in one step (or appears: it comes
  // in along its axis from where it touches no node) is moved there in stages, each solved, so
  // that no node is caught deep inside it and pushed out through its far side.
  const int stages = move_instruments(time_ + solver_.dt);
  std::vector<Eigen::Isometry3d>& from = stage_from_;
  std::vector<Eigen::Isometry3d>& to = stage_to_;
  from.clear();
  to.clear();
  for (const Instrument& in : instruments_) {
    from.push_back(in.pose_start);
    to.push_back(in.pose);
  }
  bool rotations_predicted = false;
  for (int k = 1; k <= stages && result.status != StepResult::Status::Diverged; ++k) {
    for (int i = 0; i < num_instruments(); ++i) {
      Instrument& in = instruments_[i];
      in.pose_start = in.pose;
      if (k == 1) in.pose_start = from[i];
      const double s = static_cast<double>(k) / stages;
      in.pose = make_pose((1 - s) * from[i].translation() + s * to[i].translation(),
                          Eigen::Quaterniond(from[i].linear()).slerp(s, Eigen::Quaterniond(to[i].linear())));
    }
    x_stage_ = x_;
    // Dynamic: Newton starts from the predicted state (solver.predictor), whose error is
    // O(dt^2) or O(dt^3), not O(dt): one iteration of modified Newton then lands 100x closer to
    // the converged step (README, "Fast and accurate"). Not with contacts: a predicted node
    // could start inside an instrument.
    if (dynamic && k == 1 && contacts_.empty() && solver_.predictor != SolverOptions::Predictor::None) {
      x_ += solver_.dt * v_;
      if (solver_.predictor == SolverOptions::Predictor::ConstantAcceleration) x_ += solver_.dt * (v_ - v_previous_);
      // An instrument that moved in this step may touch the prediction: start at x_n then.
      if (num_instruments() > 0) {
        detect_contacts(x_);
        if (!contacts_.empty()) {
          x_ = x_stage_;
          detect_contacts(x_);
        }
      }
      // The rotations follow the prediction as a guess (warm polar iterations), when they are
      // those of x_n.
      if (contacts_.empty() && rotations_at_.size() == x_.size() && rotations_at_ == x_stage_) {
        tetra_.predict_rotations(rotations_continued_);
        rotations_predicted = true;
      }
    }
    newton(result);
  }
  if (dynamic && result.status != StepResult::Status::Diverged && result.iterations > 0) {
    // Backward Euler dissipates: the energy cannot exceed what it had plus the work done on it.
    // A margin of 2 leaves room for the follower loads and the corotational approximation;
    // what it catches is a runaway. The energy at the start is the last step's end when known.
    const double energy_before = std::isnan(state_energy_) ? mechanical_energy(x_start_, v_) : state_energy_;
    v_tmp_ = (x_ - x_start_) / solver_.dt;
    const double energy_after = mechanical_energy(x_, v_tmp_);
    const double work = work_over_step();
    state_energy_ = energy_after;
    if (!std::isfinite(energy_after) || energy_after > 2 * (energy_before + std::abs(work)) + force_floor_ * length_scale_) {
      std::ostringstream m;
      m << "energy growth: " << energy_after << " J after the step, " << energy_before << " J before, work "
        << work << " J";
      result.status = StepResult::Status::Diverged;
      result.message = m.str();
      state_energy_ = energy_before;
    }
  } else {
    state_energy_ = std::numeric_limits<double>::quiet_NaN();
  }
  rotations_continued_ = rotations_predicted && result.status != StepResult::Status::Diverged;
  if (result.status == StepResult::Status::Diverged) {
    x_ = x_start_;
    contact_force_ = contact_force_start_;
    detect_contacts(x_);  // the contacts of the restored state (their forces are kept)
  } else {
    if (dynamic) {
      v_previous_.swap(v_);
      v_ = (x_ - x_start_) / solver_.dt;
    }
    time_ += solver_.dt;
  }
  update_reactions();
  for (const Contact& c : contacts_) result.contacts += !c.force.isZero(0.0);
  result.timing.total_ms = ms_since(t_step);
  return result;
}

double LiverModel::merit(double residual_norm, const Eigen::VectorXd& x) const {
  // A contact violation counts as the force that a stiffness E L would need to close it.
  const double k = parenchyma_.young_modulus * length_scale_ * contact_violation(x);
  return std::sqrt(residual_norm * residual_norm + k * k);
}

void LiverModel::newton(StepResult& result) {
  auto fail = [&](const std::string& why) {
    result.status = StepResult::Status::Diverged;
    result.message = why;
  };
  const int iterations_before = result.iterations;
  bool refreshed = false;  // a modified-Newton iteration on an old factor was redone on a new one
  auto t0 = Clock::now();
  double reference = 0;
  detect_contacts(x_);
  double norm = residual(x_, r_, &reference);
  const double start_merit = merit(norm, x_);
  result.timing.assembly_ms += ms_since(t0);
  result.status = StepResult::Status::NotConverged;
  while (true) {
    if (!std::isfinite(norm)) {
      fail("non-finite residual");
      break;
    }
    const double current_merit = merit(norm, x_);
    // The line search keeps the merit near its start; a millionfold growth means the iteration
    // has left the basin (possible without line search).
    if (current_merit > 1e6 * std::max(start_merit, force_floor_)) {
      std::ostringstream m;
      m << "residual blow-up: " << current_merit << " N against " << start_merit << " N at the start of the step";
      fail(m.str());
      break;
    }
    result.residual = norm / reference;
    // Relative to the forces at play; the absolute floor is round-off, for states near rest.
    // With instruments, the contact conditions must hold too.
    if (norm <= std::max(solver_.tolerance * reference, force_floor_) &&
        (contacts_.empty() || contact_violation(x_) <= contact_.tolerance)) {
      result.status = StepResult::Status::Converged;
      break;
    }
    if (result.iterations - iterations_before == solver_.max_iterations) {
      // Capped but closer to equilibrium: kept, the next step continues (real-time frames).
      // No closer after all the iterations: stalled, rolled back like a divergence.
      if (current_merit >= start_merit) {
        std::ostringstream m;
        m << "stalled: residual " << current_merit << " N after " << solver_.max_iterations
          << " iterations, no lower than the " << start_merit << " N it started from";
        fail(m.str());
      } else {
        result.message = "iteration cap";  // within the string's inline buffer: no allocation per frame
      }
      break;
    }
    ++result.iterations;
    using Strategy = SolverOptions::Strategy;
    const Strategy strategy = contacts_.empty() ? solver_.strategy : Strategy::NewtonKrylov;
    const bool current_tangent = strategy == Strategy::FullNewton || strategy == Strategy::FullNewtonEigen ||
                                 strategy == Strategy::ReusedFactorCG || strategy == Strategy::CG;
    if (strategy == Strategy::FullNewton) factor_valid_ = false;
    const bool uses_factor = strategy != Strategy::FullNewtonEigen && strategy != Strategy::CG;
    if (!factor_valid_ || current_tangent) {
      t0 = Clock::now();
      assemble_system();
      result.timing.assembly_ms += ms_since(t0);
    }
    if (strategy == Strategy::FullNewtonEigen) {
      t0 = Clock::now();
      const Eigen::Map<const Eigen::SparseMatrix<double>> A(pattern_.rows(), pattern_.rows(), pattern_.nonzeros(),
                                                            pattern_.column_start().data(), pattern_.row_index().data(),
                                                            system_.data());
      if (!eigen_analyzed_) eigen_ldlt_.analyzePattern(A);
      eigen_analyzed_ = true;
      eigen_ldlt_.factorize(A);
      result.timing.factorization_ms += ms_since(t0);
      ++result.factorizations;
      if (eigen_ldlt_.info() != Eigen::Success || (eigen_ldlt_.vectorD().array() <= 0).any()) {
        fail("tangent matrix is not positive definite");
        break;
      }
    }
    // The factor of an earlier tangent keeps serving as the preconditioner (GMRES works on the
    // true Jacobian) until it no longer preconditions well or the constraints changed.
    const bool fresh_factor = uses_factor && !factor_valid_;
    if (fresh_factor) {
      t0 = Clock::now();
      const bool factored = solver_cholmod_.factorize(system_);
      result.timing.factorization_ms += ms_since(t0);
      ++result.factorizations;
      if (!factored) {
        fail("tangent matrix is not positive definite");
        break;
      }
      factor_valid_ = true;
    }
    // Newton-Krylov: GMRES on the true Jacobian (directional differences of the residual),
    // preconditioned by the factorised corotational tangent. The tangent alone misses the
    // rotation derivative and the follower-load stiffness, which under suction on soft tissue
    // are as large as the material stiffness and make a plain modified Newton crawl.
    t0 = Clock::now();
    // A factorisation costs far more than a GMRES iteration: solve each linearisation well.
    const double forcing = std::clamp(0.1 * solver_.tolerance * reference / current_merit, 1e-6, 0.1);
    const Gmres::Operator jacobian = [&](const Eigen::VectorXd& v, Eigen::VectorXd& out) {
      const double h = 1e-8 * length_scale_ / std::max(v.cwiseAbs().maxCoeff(), 1e-300);
      x_try_ = x_ + h * v;
      double unused;
      residual(x_try_, out, &unused);
      for (int i = 0; i < out.size(); ++i) out[i] = fixed_dof_[i] ? v[i] : (r_[i] - out[i]) / h;
    };
    const Gmres::Operator preconditioner = [&](const Eigen::VectorXd& in, Eigen::VectorXd& out) {
      solver_cholmod_.solve(in, out);
    };
    const Gmres::Operator tangent = [&](const Eigen::VectorXd& v, Eigen::VectorXd& out) {
      pattern_.multiply(system_, v, out);
    };
    int krylov = 0;
    if (strategy == Strategy::FullNewton || strategy == Strategy::ModifiedNewton) {
      solver_cholmod_.solve(r_, dx_);
    } else if (strategy == Strategy::FullNewtonEigen) {
      dx_ = eigen_ldlt_.solve(r_);
    } else if (strategy == Strategy::ReusedFactorCG) {
      krylov = cg_.solve(tangent, preconditioner, r_, dx_, forcing, kMaxKrylov);
      if (krylov > kRefactorAfter || cg_.relative_residual() > forcing) factor_valid_ = false;
    } else if (strategy == Strategy::CG) {
      jacobi_.resize(pattern_.rows());
      for (int i = 0; i < pattern_.rows(); ++i) jacobi_[i] = 1.0 / system_[pattern_.diagonal(i)];
      const Gmres::Operator jacobi = [&](const Eigen::VectorXd& in, Eigen::VectorXd& out) { out = jacobi_.cwiseProduct(in); };
      krylov = cg_.solve(tangent, jacobi, r_, dx_, forcing, 20 * kMaxKrylov * kMaxKrylov);
    } else if (contacts_.empty()) {
      krylov = gmres_.solve(jacobian, preconditioner, r_, dx_, forcing, kMaxKrylov);
      if (krylov > kRefactorAfter || gmres_.relative_residual() > forcing) factor_valid_ = false;
    } else {
      const auto t_contact = Clock::now();
      krylov = contact_update(jacobian, forcing, result);
      result.timing.contact_ms += ms_since(t_contact);
      if (krylov > kRefactorAfter || gmres_.relative_residual() > forcing) factor_valid_ = false;
    }
    result.linear_iterations += krylov;
    result.timing.solve_ms += ms_since(t0);
    if (!dx_.allFinite()) {
      fail("non-finite Newton update");
      break;
    }

    // Backtracking guards far from the solution. A step is accepted when the merit (free
    // residual and constraint gap) falls enough, or when the potential falls along it: the slope
    // r . dx at the trial point, against the slope at the start, says so (trapezoid rule). The
    // second test keeps full steps that raise the residual only because the linear step
    // over-stretches rotating elements, as in the first step of a bending problem.
    t0 = Clock::now();
    double slope0 = 0;
    for (int i = 0; i < r_.size(); ++i)
      if (!fixed_dof_[i]) slope0 += r_[i] * dx_[i];
    double alpha = 1.0, best_alpha = 1.0, best_norm = 0, best_merit = std::numeric_limits<double>::infinity();
    double ref_try = reference;
    const int max_halvings = solver_.line_search ? 6 : 0;
    bool accepted = false;  // a trial passed the merit or the potential test
    for (int h = 0;; ++h) {
      x_try_ = x_ + alpha * dx_;
      const double n_try = residual(x_try_, r_try_, &ref_try);
      const double m_try = merit(n_try, x_try_);
      const bool merit_falls = m_try <= (1.0 - 1e-4 * alpha) * current_merit;
      const bool potential_falls = std::isfinite(m_try) && slope0 > 0 && r_try_.dot(dx_) >= -0.5 * slope0;
      if (merit_falls || potential_falls || m_try < best_merit) {
        best_merit = m_try;
        best_norm = n_try;
        best_alpha = alpha;
      }
      accepted = merit_falls || potential_falls;
      if (accepted || h == max_halvings) break;
      alpha *= 0.5;
    }
    // None was good enough: take the best one tried.
    if (best_alpha != alpha) {
      x_try_ = x_ + best_alpha * dx_;
      best_norm = residual(x_try_, r_try_, &ref_try);
    }
    result.timing.assembly_ms += ms_since(t0);
    // Modified Newton on an old factor that finds no descent (no trial accepted, or only by the
    // potential test in the last iteration allowed, which would end the step above where it
    // started and roll it back as stalled): the factor no longer fits the state. Refactorise
    // at x (evaluated again: the tangent is assembled where the last evaluation was) and redo
    // the iteration, once per Newton solve (per instrument stage), instead of spending it.
    const bool last_iteration = result.iterations - iterations_before == solver_.max_iterations;
    if (strategy == Strategy::ModifiedNewton && !fresh_factor && !refreshed && best_merit >= current_merit &&
        (!accepted || last_iteration)) {
      refreshed = true;
      factor_valid_ = false;
      --result.iterations;
      norm = residual(x_, r_, &reference);
      continue;
    }
    x_.swap(x_try_);
    r_.swap(r_try_);
    // Modified Newton keeps its factor while it contracts the residual well.
    if (strategy == Strategy::ModifiedNewton && best_norm > 0.9 * norm) factor_valid_ = false;
    norm = best_norm;
    reference = ref_try;
    if (detect_contacts(x_)) norm = residual(x_, r_, &reference);
  }
}

int LiverModel::add_instrument(const InstrumentOptions& o) {
  require_valid(validate(o));
  if (find_instrument(o.name) >= 0) throw std::invalid_argument("instruments." + o.name + ": the name is taken");
  Instrument in;
  in.options = o;
  in.pose = in.pose_start = pose_at(o, time_);
  if (o.type == InstrumentOptions::Type::Tube) {
    in.suction_load = static_cast<int>(pressures_.size());
    pressures_.push_back({0.0, {}});
  }
  instruments_.push_back(std::move(in));
  return num_instruments() - 1;
}

void LiverModel::update_instrument(int i, const InstrumentOptions& o) {
  require_valid(validate(o));
  if (o.type != instruments_[i].options.type || o.name != instruments_[i].options.name)
    throw std::invalid_argument("instruments." + instruments_[i].options.name + ": name and type cannot change");
  instruments_[i].options = o;
}

int LiverModel::find_instrument(const std::string& name) const {
  for (int i = 0; i < num_instruments(); ++i)
    if (instruments_[i].options.name == name) return i;
  return -1;
}

int LiverModel::move_instruments(double t) {
  int stages = 1;
  for (Instrument& in : instruments_) {
    const InstrumentOptions& o = in.options;
    in.pose_start = in.pose;
    in.pose = pose_at(o, t);
    if (o.enabled && o.type != InstrumentOptions::Type::Grasper) {
      const double size = o.type == InstrumentOptions::Type::Tube ? o.outer_radius - o.inner_radius : o.radius;
      if (!in.was_enabled) {
        // It appears: it comes in along its axis from where it touches no node.
        double depth = 0;
        for (int node : boundary_nodes_)
          depth = std::max(depth, -surface_distance(o, in.pose, x_.segment<3>(3 * node)).distance);
        in.pose_start = in.pose;
        in.pose_start.translation() += depth * in.pose.linear().col(2);
      }
      const double travel = (in.pose.translation() - in.pose_start.translation()).norm();
      stages = std::max(stages, std::min(kMaxStages, static_cast<int>(std::ceil(travel / (0.25 * size)))));
    }
    in.was_enabled = o.enabled;
    if (o.type == InstrumentOptions::Type::Grasper) {
      const bool closed = o.enabled && closed_at(o, t);
      if (closed && !in.closed) {
        // The jaws close on the surface nodes within reach, where they are at this instant.
        for (int node : boundary_nodes_) {
          const Eigen::Vector3d x = x_.segment<3>(3 * node);
          if (fixed_by_scene_[node] || (x - in.pose_start.translation()).norm() > o.radius) continue;
          in.held.push_back(node);
          in.held_local.push_back(in.pose_start.inverse() * x);
        }
      } else if (!closed) {
        in.held.clear();
        in.held_local.clear();
      }
      in.closed = closed;
    }
    if (in.suction_load >= 0) {
      // Suction acts on the surface inside the lumen as the step starts.
      PressureLoad& load = pressures_[in.suction_load];
      load.pressure = -o.suction;
      load.triangles.clear();
      if (!o.enabled || o.suction == 0) continue;
      for (int f = 0; f < boundary_.rows(); ++f) {
        const Eigen::Vector3d a = x_.segment<3>(3 * boundary_(f, 0)), b = x_.segment<3>(3 * boundary_(f, 1)),
                              c = x_.segment<3>(3 * boundary_(f, 2));
        if (in_tube_lumen(o, in.pose, (a + b + c) / 3, (b - a).cross(c - a))) load.triangles.push_back(f);
      }
    }
  }
  return stages;
}

bool LiverModel::detect_contacts(const Eigen::VectorXd& x) {
  // Contacts are listed by instrument, then node: the previous forces are matched in one pass.
  contacts_next_.clear();
  for (int k = 0; k < num_instruments(); ++k) {
    const Instrument& in = instruments_[k];
    if (!in.options.enabled) continue;
    if (in.options.type == InstrumentOptions::Type::Grasper) {
      for (int node : in.held)
        contacts_next_.push_back({k, node, true, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()});
      continue;
    }
    for (int node : boundary_nodes_) {
      if (fixed_by_scene_[node]) continue;  // the scene holds those already
      if (surface_distance(in.options, in.pose, x.segment<3>(3 * node)).distance >= contact_.alarm_distance) continue;
      contacts_next_.push_back({k, node, false, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()});
    }
  }
  bool dropped_force = false;
  size_t j = 0;
  for (Contact& c : contacts_next_) {
    while (j < contacts_.size() && std::make_pair(contacts_[j].instrument, contacts_[j].node) < std::make_pair(c.instrument, c.node)) {
      dropped_force |= !contacts_[j].force.isZero(0.0);
      ++j;
    }
    if (j < contacts_.size() && contacts_[j].instrument == c.instrument && contacts_[j].node == c.node) c.force = contacts_[j++].force;
  }
  for (; j < contacts_.size(); ++j) dropped_force |= !contacts_[j].force.isZero(0.0);
  contacts_.swap(contacts_next_);
  for (size_t c = 0; c < contacts_.size(); ++c) contacts_[c].rows = contact_rows(static_cast<int>(c), x, &contacts_[c].frame);
  if (dropped_force) {
    contact_force_.setZero();
    for (const Contact& c : contacts_) contact_force_.segment<3>(3 * c.node) += c.force;
  }
  return dropped_force;
}

Eigen::Vector3d LiverModel::contact_rows(int c, const Eigen::VectorXd& x, Eigen::Matrix3d* frame) const {
  const Contact& contact = contacts_[c];
  const Instrument& in = instruments_[contact.instrument];
  const Eigen::Vector3d p = x.segment<3>(3 * contact.node);
  if (contact.bilateral) {
    const auto it = std::find(in.held.begin(), in.held.end(), contact.node);
    frame->setIdentity();
    return p - in.pose * in.held_local[it - in.held.begin()];
  }
  const SurfaceDistance d = surface_distance(in.options, in.pose, p);
  // Tangents: any orthonormal pair (forces are carried between iterations in the world frame).
  const Eigen::Vector3d helper = std::abs(d.normal.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d t1 = d.normal.cross(helper).normalized();
  frame->col(0) = d.normal;
  frame->col(1) = t1;
  frame->col(2) = d.normal.cross(t1);
  // Slip over the step: against the instrument point that was under the node at its start.
  const Eigen::Vector3d p0 = x_stage_.segment<3>(3 * contact.node);
  const Eigen::Vector3d slip = p - in.pose * (in.pose_start.inverse() * p0);
  return Eigen::Vector3d(d.distance, frame->col(1).dot(slip), frame->col(2).dot(slip));
}

double LiverModel::contact_violation(const Eigen::VectorXd& x) const {
  double worst = 0;
  Eigen::Matrix3d frame;
  for (size_t c = 0; c < contacts_.size(); ++c) {
    const Contact& contact = contacts_[c];
    const Eigen::Vector3d rows = contact_rows(static_cast<int>(c), x, &frame);
    if (contact.bilateral) {
      worst = std::max(worst, rows.cwiseAbs().maxCoeff());
      continue;
    }
    const Eigen::Vector3d lambda = frame.transpose() * contact.force;
    worst = std::max(worst, lambda[0] > 0 ? std::abs(rows[0]) : -rows[0]);  // Signorini
    const double cone = contact_.friction * lambda[0];
    if (lambda[0] > 0 && lambda.tail<2>().norm() < cone * (1 - 1e-6))  // strictly inside: sticks
      worst = std::max(worst, rows.tail<2>().norm());
  }
  return worst;
}

int LiverModel::contact_update(const std::function<void(const Eigen::VectorXd&, Eigen::VectorXd&)>& jacobian,
                               double forcing, StepResult& result) {
  // 1. Compliance columns of the factor now in use: the nodes that lack them, in one solve.
  if (compliance_factor_ != solver_cholmod_.factorizations()) {
    for (int node : compliance_nodes_) compliance_slot_[node] = -1;
    compliance_nodes_.clear();
    compliance_factor_ = solver_cholmod_.factorizations();
  }
  std::vector<int>& missing = missing_nodes_;
  missing.clear();
  for (const Contact& c : contacts_)
    if (compliance_slot_[c.node] < 0 && std::find(missing.begin(), missing.end(), c.node) == missing.end())
      missing.push_back(c.node);
  const Eigen::Index dofs = x_.size();
  if (!missing.empty()) {
    rhs_columns_.setZero(dofs, 3 * static_cast<Eigen::Index>(missing.size()));
    for (size_t k = 0; k < missing.size(); ++k)
      for (int d = 0; d < 3; ++d) rhs_columns_(3 * missing[k] + d, 3 * k + d) = 1.0;
    solver_cholmod_.solve(rhs_columns_, new_columns_);
    const Eigen::Index used = static_cast<Eigen::Index>(compliance_nodes_.size());
    const Eigen::Index needed = 3 * (used + static_cast<Eigen::Index>(missing.size()));
    if (compliance_.cols() < needed) compliance_.conservativeResize(dofs, std::max<Eigen::Index>(needed, 2 * compliance_.cols()));
    compliance_.middleCols(3 * used, new_columns_.cols()) = new_columns_;
    for (int node : missing) {
      compliance_slot_[node] = static_cast<int>(compliance_nodes_.size());
      compliance_nodes_.push_back(node);
    }
    compliance_columns_ += new_columns_.cols();
  }
  auto columns = [&](int node) {
    return Eigen::Map<const Eigen::MatrixXd>(compliance_.data() + 3 * compliance_slot_[node] * dofs, dofs, 3);
  };

  // 2. The frictional contact problem on the Delassus operator W = H A^-1 H^T, with the rows
  // predicted after the tangent's update A^-1 r: which contacts separate, stick or slide.
  solver_cholmod_.solve(r_, dx_);
  const int m = static_cast<int>(contacts_.size());
  delassus_.resize(3 * m, 3 * m);
  contact_delta_.resize(3 * m);
  contact_lambda_.resize(3 * m);
  contact_bilateral_.resize(m);
  for (int d = 0; d < m; ++d) {
    const auto G = columns(contacts_[d].node);
    for (int c = 0; c < m; ++c)
      delassus_.block<3, 3>(3 * c, 3 * d) =
          contacts_[c].frame.transpose() * G.middleRows<3>(3 * contacts_[c].node) * contacts_[d].frame;
  }
  for (int c = 0; c < m; ++c) {
    const Contact& contact = contacts_[c];
    contact_delta_.segment<3>(3 * c) = contact.rows + contact.frame.transpose() * dx_.segment<3>(3 * contact.node);
    contact_lambda_.segment<3>(3 * c) = contact.frame.transpose() * contact.force;
    contact_bilateral_[c] = contact.bilateral;
  }
  const ContactSolveResult solved = solve_frictional_contacts(delassus_, contact_delta_, contact_bilateral_, contact_.friction,
                                                              0.01 * contact_.tolerance, contact_.max_iterations, contact_lambda_);
  ++contact_solves_;
  result.contact_sweeps += solved.sweeps;

  // 3. The Newton update for that contact state, on the true Jacobian J:
  //      J dx - B lambda = r_free,   H dx = -rows
  // (sticking and held contacts: three rows and forces along the frame; sliding: the normal
  // row, and a force along n + mu t on the cone's edge; separating: none). GMRES, preconditioned
  // by the same system with the tangent A, which the compliance columns solve exactly:
  // lambda = S^-1 (g - H A^-1 u), dx = A^-1 (u + B lambda), S = H A^-1 B.
  unknown_rows_.clear();
  for (int c = 0; c < m; ++c) {
    const Contact& contact = contacts_[c];
    const Eigen::Vector3d lambda = contact_lambda_.segment<3>(3 * c);
    const double cone = contact_.friction * lambda[0];
    if (contact.bilateral || (lambda[0] > 0 && contact_.friction > 0 && lambda.tail<2>().norm() < cone * (1 - 1e-9))) {
      for (int k = 0; k < 3; ++k) unknown_rows_.push_back({c, contact.frame.col(k), contact.frame.col(k), -contact.rows[k]});
    } else if (lambda[0] > 0) {
      Eigen::Vector3d direction = contact.frame.col(0);
      if (contact_.friction > 0) direction += contact.frame.rightCols<2>() * (lambda.tail<2>() / lambda[0]);
      unknown_rows_.push_back({c, contact.frame.col(0), direction, -contact.rows[0]});
    }
  }
  const int k = static_cast<int>(unknown_rows_.size());
  schur_.resize(k, k);
  for (int b = 0; b < k; ++b) {
    const auto G = columns(contacts_[unknown_rows_[b].contact].node);
    for (int a = 0; a < k; ++a)
      schur_(a, b) = unknown_rows_[a].row.dot(G.middleRows<3>(3 * contacts_[unknown_rows_[a].contact].node) * unknown_rows_[b].force);
  }
  schur_lu_.compute(schur_);
  augmented_rhs_.resize(dofs + k);
  augmented_rhs_.head(dofs) = r_ - contact_force_;
  for (int a = 0; a < k; ++a) augmented_rhs_[dofs + a] = unknown_rows_[a].target;
  const Gmres::Operator system = [&](const Eigen::VectorXd& z, Eigen::VectorXd& out) {
    augmented_dx_ = z.head(dofs);
    jacobian(augmented_dx_, augmented_out_);
    out.resize(dofs + k);
    out.head(dofs) = augmented_out_;
    for (int a = 0; a < k; ++a) {
      const int node = contacts_[unknown_rows_[a].contact].node;
      out.segment<3>(3 * node) -= unknown_rows_[a].force * z[dofs + a];
      out[dofs + a] = unknown_rows_[a].row.dot(z.segment<3>(3 * node));
    }
  };
  const Gmres::Operator preconditioner = [&](const Eigen::VectorXd& in, Eigen::VectorXd& out) {
    augmented_dx_ = in.head(dofs);
    solver_cholmod_.solve(augmented_dx_, augmented_out_);
    schur_rhs_.resize(k);
    for (int a = 0; a < k; ++a)
      schur_rhs_[a] = in[dofs + a] - unknown_rows_[a].row.dot(augmented_out_.segment<3>(3 * contacts_[unknown_rows_[a].contact].node));
    schur_solution_ = schur_lu_.solve(schur_rhs_);
    out.resize(dofs + k);
    for (int a = 0; a < k; ++a)
      augmented_out_ += columns(contacts_[unknown_rows_[a].contact].node) * (unknown_rows_[a].force * schur_solution_[a]);
    out.head(dofs) = augmented_out_;
    out.tail(k) = schur_solution_;
  };
  const int krylov = gmres_.solve(system, preconditioner, augmented_rhs_, augmented_solution_, forcing, kMaxKrylov);
  dx_ = augmented_solution_.head(dofs);
  contact_force_.setZero();
  for (Contact& c : contacts_) c.force.setZero();
  for (int a = 0; a < k; ++a) {
    Contact& c = contacts_[unknown_rows_[a].contact];
    c.force += unknown_rows_[a].force * augmented_solution_[dofs + a];
    contact_force_.segment<3>(3 * c.node) += unknown_rows_[a].force * augmented_solution_[dofs + a];
  }
  return krylov;
}

void LiverModel::update_reactions() {
  for (Instrument& in : instruments_) in.reaction = InstrumentReaction{};
  for (const Contact& c : contacts_) {
    if (c.force.isZero(0.0)) continue;
    InstrumentReaction& r = instruments_[c.instrument].reaction;
    r.force -= c.force;
    r.torque -= (x_.segment<3>(3 * c.node) - instruments_[c.instrument].pose.translation()).cross(c.force);
    ++r.contacts;
  }
}

Eigen::VectorXd LiverModel::support_forces() {
  double unused;
  residual(x_, r_try_, &unused, /*zero_fixed=*/false);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(x_.size());
  for (int i = 0; i < f.size(); ++i)
    if (fixed_dof_[i]) f[i] = -r_try_[i];  // the support balances the residual
  return f;
}

}  // namespace liver_sim
