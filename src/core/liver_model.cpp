#include "liver_sim/liver_model.h"

#include <Eigen/Geometry>
#include <Eigen/LU>
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
      membrane_(mesh_.V, boundary_, capsule_) {
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
  damping_stiffness_.assign(pattern_.nonzeros(), 0.0);
  system_.assign(pattern_.nonzeros(), 0.0);
  solver_cholmod_.analyze(pattern_.rows(), pattern_.column_start(), pattern_.row_index());

  X_ = flatten(mesh_.V);
  x_ = X_;
  target_ = X_;
  v_ = Eigen::VectorXd::Zero(dofs);
  x_start_ = X_;
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
  released_.assign(n, 0);

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

  for (Eigen::VectorXd* v : {&r_, &r_try_, &dx_, &x_try_, &f_tmp_, &v_tmp_, &f_ext_, &energy_work_}) v->setZero(dofs);
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
  capsule_active_ = std::move(active);
  capsule_ = capsule;
  factor_valid_ = false;
  return "";
}

int LiverModel::capsule_triangles() const {
  return capsule_.enabled ? static_cast<int>(capsule_active_.size()) : 0;
}

void LiverModel::reset() {
  factor_valid_ = false;
  state_energy_ = std::numeric_limits<double>::quiet_NaN();
  x_ = X_;
  target_ = X_;
  contact_nodes_.clear();
  set_fixed(scene_fixed_nodes_);
  probe_reaction_ = ProbeReaction{};
  std::fill(released_.begin(), released_.end(), 0);
  v_.setZero();
  x_start_ = X_;
  time_ = 0;
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
  f.setZero(x.size());
  tetra_.update_rotations(x);
  Vector12d fe;
  for (int e = 0; e < tetra_.size(); ++e) {
    tetra_.element_force(e, x, fe);
    for (int k = 0; k < 4; ++k) f.segment<3>(3 * mesh_.T(e, k)) += fe.segment<3>(3 * k);
  }
  if (capsule_.enabled) {
    membrane_.update_rotations(x);
    Vector9d fm;
    for (int t : capsule_active_) {
      membrane_.element_force(t, x, fm);
      for (int k = 0; k < 3; ++k) f.segment<3>(3 * boundary_(t, k)) += fm.segment<3>(3 * k);
    }
  }
  if (beams_) add_beam_forces(x, f);
}

void LiverModel::add_beam_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) {
  for (size_t h = 0; h < hosts_.size(); ++h) {
    const Eigen::Matrix3d F = tetra_.deformation_gradient(hosts_[h], x);
    host_rotation_[h] = polar_rotation(F);
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
  internal_forces(x, energy_work_);  // brings every rotation and beam frame to x
  double energy = 0;
  for (int e = 0; e < tetra_.size(); ++e) energy += tetra_.element_energy(e, x);
  if (capsule_.enabled)
    for (int t : capsule_active_) energy += membrane_.element_energy(t, x);
  for (int e = 0; e < num_beams(); ++e) energy += beams_->element_energy(e);
  return energy;
}

double LiverModel::mechanical_energy(const Eigen::VectorXd& x, const Eigen::VectorXd& v) {
  return 0.5 * v.dot(mass_.cwiseProduct(v)) + elastic_energy(x);
}

double LiverModel::work_over_step() {
  // Loads: trapezoid rule between the start and the end of the step. Constraints (a probe; the
  // scene's fixed nodes do not move): their force at the end, -r at the constrained DOFs, times
  // the displacement.
  external_forces(x_start_, f_ext_);
  external_forces(x_, energy_work_);
  f_ext_ = 0.5 * load_scale_ * (f_ext_ + energy_work_);
  if (!contact_nodes_.empty()) {
    double unused;
    residual(x_, r_try_, &unused, /*zero_fixed=*/false);
  }
  double work = 0;
  for (int i = 0; i < x_.size(); ++i) {
    if (!fixed_dof_[i])
      work += (x_[i] - x_start_[i]) * f_ext_[i];
    else if (!contact_nodes_.empty())
      work -= (x_[i] - x_start_[i]) * r_try_[i];
  }
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

double LiverModel::residual(const Eigen::VectorXd& x, Eigen::VectorXd& r, double* reference, bool zero_fixed) {
  internal_forces(x, f_tmp_);
  external_forces(x, r);
  r *= load_scale_;
  const double load_norm = free_norm(r, fixed_dof_);
  // All DOFs: under prescribed displacements alone the reactions are the force scale.
  const double internal_norm = f_tmp_.norm();
  r -= f_tmp_;
  if (solver_.mode == SolverOptions::Mode::Dynamic) {
    const double dt = solver_.dt;
    // Backward Euler: M (v - v_n)/dt + D v = f_ext - f_int, v = (x - x_n)/dt, D = a M + b K.
    v_tmp_ = (x - x_start_) / dt;
    r -= mass_.cwiseProduct((v_tmp_ - v_) / dt + solver_.rayleigh_mass * v_tmp_);
    if (solver_.rayleigh_stiffness > 0) {
      pattern_.multiply(damping_stiffness_, v_tmp_, f_tmp_);
      r -= solver_.rayleigh_stiffness * f_tmp_;
    }
  }
  for (int i = 0; zero_fixed && i < r.size(); ++i)
    if (fixed_dof_[i]) r[i] = 0;
  *reference = std::max({load_norm, internal_norm, force_floor_});
  return r.norm();
}

void LiverModel::assemble_system() {
  std::fill(stiffness_.begin(), stiffness_.end(), 0.0);
  Matrix12d Ke;
  for (int e = 0; e < tetra_.size(); ++e) {
    tetra_.element_tangent(e, Ke);
    scatter_add(Ke, &tet_map_[144 * e], stiffness_);
  }
  if (capsule_.enabled) {
    Matrix9d Km;
    for (int t : capsule_active_) {
      membrane_.element_tangent(t, Km);
      scatter_add(Km, &tri_map_[81 * t], stiffness_);
    }
  }
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
  const bool dynamic = solver_.mode == SolverOptions::Mode::Dynamic;
  // Sphere probe: constrain the penetrating nodes, solve, release the nodes the probe would have
  // to pull, solve again (a few active-set passes; the next step continues from there).
  for (int pass = 0;; ++pass) {
    if (probe_) update_contacts();
    newton(result);
    if (result.status == StepResult::Status::Diverged || !probe_ || !release_tensile_contacts() || pass == 3)
      break;
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
  if (result.status == StepResult::Status::Diverged) {
    x_ = x_start_;
    contact_nodes_.clear();  // re-established from the restored state at the next step
    set_fixed(scene_fixed_nodes_);
  }
  update_probe_reaction();  // before the velocity update: the residual needs v_n
  if (result.status != StepResult::Status::Diverged && dynamic) {
    v_ = (x_ - x_start_) / solver_.dt;
    time_ += solver_.dt;
  }
  result.timing.total_ms = ms_since(t_step);
  return result;
}

double LiverModel::merit(double residual_norm, const Eigen::VectorXd& x) const {
  // A gap in a prescribed position counts as the force that a stiffness E L would need to close it.
  const double k = parenchyma_.young_modulus * length_scale_;
  double gap2 = 0;
  for (int i = 0; i < x.size(); ++i)
    if (fixed_dof_[i]) gap2 += (target_[i] - x[i]) * (target_[i] - x[i]);
  return std::sqrt(residual_norm * residual_norm + k * k * gap2);
}

void LiverModel::newton(StepResult& result) {
  auto fail = [&](const std::string& why) {
    result.status = StepResult::Status::Diverged;
    result.message = why;
  };
  const int iterations_before = result.iterations;
  auto t0 = Clock::now();
  double reference = 0;
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
    // Prescribed positions not reached yet (a probe just moved) are part of the next update.
    double gap = 0;
    for (int i = 0; i < r_.size(); ++i)
      if (fixed_dof_[i]) gap = std::max(gap, std::abs(target_[i] - x_[i]));
    // Relative to the forces at play; the absolute floor is round-off, for states near rest.
    if (norm <= std::max(solver_.tolerance * reference, force_floor_) && gap <= 1e-12 * length_scale_) {
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
        result.message = "iteration cap reached";
      }
      break;
    }
    ++result.iterations;
    // Rayleigh damping uses the stiffness at the start of the step, fixed within the step, so
    // that the residual stays one function of x while Newton iterates. (v = 0 there, so the
    // residual already computed is unchanged.)
    const bool damping_snapshot = result.iterations == 1 && solver_.mode == SolverOptions::Mode::Dynamic &&
                                  solver_.rayleigh_stiffness > 0;
    if (!factor_valid_ || damping_snapshot) {
      t0 = Clock::now();
      assemble_system();
      if (damping_snapshot) damping_stiffness_ = stiffness_;
      result.timing.assembly_ms += ms_since(t0);
    }
    // The factor of an earlier tangent keeps serving as the preconditioner (GMRES works on the
    // true Jacobian) until it no longer preconditions well or the constraints changed.
    if (!factor_valid_) {
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
    // Constrained rows are identity with the remaining gap on the right-hand side, so that the
    // free nodes follow the prescribed ones in the same linear solve (consistent lifting).
    for (int i = 0; i < r_.size(); ++i)
      if (fixed_dof_[i]) r_[i] = target_[i] - x_[i];
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
    const int krylov = gmres_.solve(jacobian, preconditioner, r_, dx_, forcing, kMaxKrylov);
    result.linear_iterations += krylov;
    result.timing.solve_ms += ms_since(t0);
    if (krylov > kRefactorAfter || gmres_.relative_residual() > forcing) factor_valid_ = false;
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
      if (merit_falls || potential_falls || h == max_halvings) break;
      alpha *= 0.5;
    }
    // None was good enough: take the best one tried.
    if (best_alpha != alpha) {
      x_try_ = x_ + best_alpha * dx_;
      best_norm = residual(x_try_, r_try_, &ref_try);
    }
    result.timing.assembly_ms += ms_since(t0);
    x_.swap(x_try_);
    r_.swap(r_try_);
    norm = best_norm;
    reference = ref_try;
  }
}

void LiverModel::set_sphere_probe(const Eigen::Vector3d& centre, double radius) {
  if (!centre.allFinite() || !std::isfinite(radius) || radius <= 0)
    throw std::invalid_argument("sphere probe: centre must be finite and radius > 0");
  if (probe_ && probe_->centre == centre && probe_->radius == radius) return;
  probe_ = SphereProbe{centre, radius};
  // Released nodes stay free until the probe moves: without it a node that the probe would have
  // to pull can cycle between contact and release from one step to the next.
  std::fill(released_.begin(), released_.end(), 0);
}

void LiverModel::remove_sphere_probe() {
  probe_.reset();
  contact_nodes_.clear();
  set_fixed(scene_fixed_nodes_);
  update_probe_reaction();
}

void LiverModel::update_contacts() {
  // Outward vertex normals of the current surface (area-weighted).
  node_normal_.setZero(x_.size());
  for (int f = 0; f < boundary_.rows(); ++f) {
    const int a = boundary_(f, 0), b = boundary_(f, 1), c = boundary_(f, 2);
    const Eigen::Vector3d area = (x_.segment<3>(3 * b) - x_.segment<3>(3 * a)).cross(x_.segment<3>(3 * c) - x_.segment<3>(3 * a));
    for (int k : {a, b, c}) node_normal_.segment<3>(3 * k) += area;
  }
  contact_nodes_.clear();
  const double r = probe_->radius;
  for (int i : boundary_nodes_) {
    if (released_[i] || fixed_by_scene_[i]) continue;  // the scene holds those already
    const Eigen::Vector3d x = x_.segment<3>(3 * i);
    const Eigen::Vector3d d = x - probe_->centre;
    const double dist = d.norm();
    if (dist >= r * (1 + 1e-9)) continue;
    if (dist > r * (1 - 1e-9)) {
      target_.segment<3>(3 * i) = x;  // on the surface since the last step: it sticks
    } else {
      // Inside: push the node into the tissue (against its outward normal) to where that line
      // leaves the sphere, as the probe would have carried it on its way in. A radial projection
      // would pull nodes above the centre of a deep probe out of the tissue.
      const Eigen::Vector3d n = node_normal_.segment<3>(3 * i).normalized();
      const double b = n.dot(d);  // |d - t n| = r
      const double t = b + std::sqrt(b * b + r * r - dist * dist);
      target_.segment<3>(3 * i) = x - t * n;
    }
    contact_nodes_.push_back(i);
  }
  constrained_nodes_.assign(scene_fixed_nodes_.begin(), scene_fixed_nodes_.end());
  constrained_nodes_.insert(constrained_nodes_.end(), contact_nodes_.begin(), contact_nodes_.end());
  set_fixed(constrained_nodes_);
}

bool LiverModel::release_tensile_contacts() {
  double unused;
  residual(x_, r_try_, &unused, /*zero_fixed=*/false);
  bool released = false;
  for (int i : contact_nodes_) {
    // r = f_ext - f_int; the probe supplies -r. It can push the node outward, never pull it.
    const Eigen::Vector3d n = (x_.segment<3>(3 * i) - probe_->centre).normalized();
    if (r_try_.segment<3>(3 * i).dot(n) > 0) {
      released_[i] = 1;
      released = true;
    }
  }
  return released;
}

void LiverModel::update_probe_reaction() {
  probe_reaction_ = ProbeReaction{};
  if (!probe_) return;
  double unused;
  residual(x_, r_try_, &unused, /*zero_fixed=*/false);
  for (int i : contact_nodes_) {
    const Eigen::Vector3d f = r_try_.segment<3>(3 * i);  // tissue on probe
    probe_reaction_.force += f;
    probe_reaction_.torque += (x_.segment<3>(3 * i) - probe_->centre).cross(f);
  }
  probe_reaction_.contacts = static_cast<int>(contact_nodes_.size());
}

}  // namespace liver_sim
