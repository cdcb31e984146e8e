#include "liver_sim/model/mechanical_model.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace liver_sim {
namespace {

void require_valid(const std::string& message) {
  if (!message.empty()) throw std::invalid_argument(message);
}

TetMesh validated(TetMesh mesh) {
  validate_mesh(mesh, "mesh");
  return mesh;
}

template <typename Options>
const Options& validated(const Options& o) {
  require_valid(validate(o));
  return o;
}

// Chunks of the element loops: long enough that claiming one costs nothing, short enough that a
// helper taken off the processor in the middle of one holds the others up briefly.
constexpr int kBlocksPerChunk = 16;      // blocks of four tetrahedra
constexpr int kTrianglesPerChunk = 64;   // a multiple of 4: membrane frames go four at a time
constexpr int kNodesPerChunk = 256;

int chunks(int items, int per_chunk) { return (items + per_chunk - 1) / per_chunk; }

// Where each node's 3-blocks lie in the vectors of `elements` elements of k nodes (3 k doubles
// each, node_of(e, j) the j-th node of element e), in element order.
template <typename NodeOf, typename NodeGather>
void gather_nodes(int nodes, int elements, int k, const NodeOf& node_of, NodeGather& g) {
  g.start.assign(nodes + 1, 0);
  for (int e = 0; e < elements; ++e)
    for (int j = 0; j < k; ++j) ++g.start[node_of(e, j) + 1];
  for (int i = 0; i < nodes; ++i) g.start[i + 1] += g.start[i];
  g.slot.resize(g.start[nodes]);
  std::vector<int> next(g.start.begin(), g.start.end() - 1);
  for (int e = 0; e < elements; ++e)
    for (int j = 0; j < k; ++j) g.slot[next[node_of(e, j)]++] = 3 * (k * e + j);
}

Eigen::VectorXd flatten(const Eigen::MatrixX3d& V) {
  Eigen::VectorXd x(3 * V.rows());
  for (int i = 0; i < V.rows(); ++i) x.segment<3>(3 * i) = V.row(i).transpose();
  return x;
}

}  // namespace

MechanicalModel::MechanicalModel(TetMesh mesh, const Scene& scene, const std::vector<VesselTree>& vessel_trees)
    : mesh_(validated(std::move(mesh))),
      boundary_(boundary_triangles(mesh_.T)),
      parenchyma_(validated(scene.parenchyma)),
      capsule_(validated(scene.capsule)),
      tetra_(mesh_.V, mesh_.T, parenchyma_),
      membrane_(mesh_.V, boundary_, capsule_),
      vessels_(tetra_, mesh_.V, scene.vessels, vessel_trees, parenchyma_.rotation),
      workers_(validated(scene.solver).threads) {
  const int n = static_cast<int>(mesh_.V.rows());
  const int dofs = 3 * n;
  pattern_ = SparsePattern(n, mesh_.T, vessels_.coupled_nodes());
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
  beam_map_.reserve(576 * vessels_.coupled_nodes().size());
  for (const std::vector<int>& g : vessels_.coupled_nodes()) pattern_.append_scatter_map(g.data(), 8, beam_map_);
  stiffness_.assign(pattern_.nonzeros(), 0.0);
  if (workers_.threads() > 1) {
    const int tetrahedra = tetra_.size();
    element_vectors_.tet.resize(tetrahedra);
    element_vectors_.block_energy.resize((tetrahedra + 3) / 4);
    gather_nodes(n, tetrahedra, 4, [&](int e, int j) { return mesh_.T(e, j); }, element_vectors_.tet_gather);
  }

  X_ = flatten(mesh_.V);
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
  if (fixed_nodes.empty() && scene.solver.mode == SolverOptions::Mode::Static)
    throw std::invalid_argument("fixed: a static scene needs fixed nodes (the stiffness matrix is singular otherwise)");
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
    const EmbeddedPoint at = locate(tetra_, mesh_.V, p.point);
    // Points on a curved surface may sit a little outside the faceted mesh.
    if (at.barycentric.minCoeff() < -0.05) throw std::invalid_argument("probe '" + p.name + "' lies outside the mesh");
    probes_.push_back({p.name, at});
  }
  energy_work_.setZero(dofs);
}

std::vector<int> MechanicalModel::select_nodes(const Region& r, const std::string& what) const {
  require_valid(validate(r));
  std::vector<int> nodes;
  for (int i = 0; i < mesh_.V.rows(); ++i)
    if ((!r.boundary_only() || on_boundary_[i]) && r.contains(mesh_.V.row(i).transpose()))
      nodes.push_back(i);
  if (nodes.empty()) throw std::invalid_argument(what + ": the region selects no node");
  return nodes;
}

std::vector<int> MechanicalModel::select_triangles(const Region& r, const std::string& what) const {
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

void MechanicalModel::set_fixed(const std::vector<int>& nodes) {
  fixed_dof_.assign(X_.size(), 0);
  for (int node : nodes)
    for (int c = 0; c < 3; ++c) fixed_dof_[3 * node + c] = 1;
  fixed_entries_.clear();
  const auto& start = pattern_.column_start();
  const auto& rows = pattern_.row_index();
  for (int col = 0; col < pattern_.rows(); ++col)
    for (int k = start[col]; k < start[col + 1]; ++k)
      if (rows[k] != col && (fixed_dof_[col] || fixed_dof_[rows[k]])) fixed_entries_.push_back(k);
}

std::string MechanicalModel::set_capsule(const CapsuleOptions& capsule) {
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
  rotations_at_.resize(0);  // the membrane rotations may not follow the last evaluation
  capsule_active_ = std::move(active);
  capsule_ = capsule;
  if (workers_.threads() > 1) {
    const int triangles = static_cast<int>(capsule_active_.size());
    element_vectors_.membrane.resize(triangles);
    element_vectors_.membrane_energy.resize(triangles);
    gather_nodes(static_cast<int>(mesh_.V.rows()), triangles, 3,
                 [&](int i, int j) { return boundary_(capsule_active_[i], j); }, element_vectors_.membrane_gather);
  }
  return "";
}

void MechanicalModel::set_stiffness_scale(double s) {
  if (!(std::isfinite(s) && s > 0)) throw std::invalid_argument("the stiffness scale must be finite and > 0");
  if (s == stiffness_scale_) return;
  stiffness_scale_ = s;
  rotations_at_.resize(0);  // the kept forces and energy are of the old scale
}

int MechanicalModel::capsule_triangles() const {
  return capsule_.enabled ? static_cast<int>(capsule_active_.size()) : 0;
}

int MechanicalModel::add_pressure_load() {
  pressures_.push_back({0.0, {}});
  return static_cast<int>(pressures_.size()) - 1;
}

void MechanicalModel::reset() {
  tetra_.reset_rotations();
  rotations_at_.resize(0);
  surface_targets_.clear();
  surface_loads_.resize(0);
}

void MechanicalModel::save(EvaluationState& s) const {
  tetra_.save_rotations(s.tetra);
  s.membrane_frames = membrane_.frames();
  s.rotations_at = rotations_at_;
  s.internal_at = internal_at_;
  s.tissue_energy_at = tissue_energy_at_;
  s.damping_rotations = damping_.tet_rotation;
  s.damping_frames = damping_.membrane_frame;
}

void MechanicalModel::restore(const EvaluationState& s) {
  tetra_.restore_rotations(s.tetra);
  membrane_.restore_frames(s.membrane_frames);
  rotations_at_ = s.rotations_at;
  internal_at_ = s.internal_at;
  tissue_energy_at_ = s.tissue_energy_at;
  damping_.tet_rotation = s.damping_rotations;
  damping_.membrane_frame = s.damping_frames;
  if (!vessels_.empty() && rotations_at_.size() > 0) vessels_.add_forces(rotations_at_, energy_work_);
}

template <typename TetBlock, typename Triangle>
double MechanicalModel::element_pass(Eigen::Index size, Eigen::VectorXd& f, const TetBlock& tet_block,
                                     const Triangle& triangle) {
  f.setZero(size);
  const int tetrahedra = tetra_.size(), blocks = (tetrahedra + 3) / 4;
  const int triangles = capsule_.enabled ? static_cast<int>(capsule_active_.size()) : 0;
  if (workers_.threads() == 1) {  // add as it goes
    double sum = 0;
    Vector12d fe[4];
    for (int block = 0; block < blocks; ++block) {  // four at a time: see polar_rotations
      const int first = 4 * block, count = std::min(4, tetrahedra - first);
      sum += tet_block(first, count, fe);
      for (int i = 0; i < count; ++i)
        for (int k = 0; k < 4; ++k) f.segment<3>(3 * mesh_.T(first + i, k)) += fe[i].segment<3>(3 * k);
    }
    Vector9d fm;
    for (int i = 0; i < triangles; ++i) {
      const int t = capsule_active_[i];
      sum += triangle(t, fm);
      for (int k = 0; k < 3; ++k) f.segment<3>(3 * boundary_(t, k)) += fm.segment<3>(3 * k);
    }
    return sum;
  }
  // Several threads: the element vectors first, in chunks on any thread, then each node's sum in
  // the order above.
  ElementVectors& v = element_vectors_;
  const int tet_chunks = chunks(blocks, kBlocksPerChunk);
  workers_.run(tet_chunks + chunks(triangles, kTrianglesPerChunk), [&](int chunk) {
    if (chunk < tet_chunks) {
      for (int block = chunk * kBlocksPerChunk; block < std::min(blocks, (chunk + 1) * kBlocksPerChunk); ++block) {
        const int first = 4 * block;
        v.block_energy[block] = tet_block(first, std::min(4, tetrahedra - first), &v.tet[first]);
      }
    } else {
      const int first = (chunk - tet_chunks) * kTrianglesPerChunk;
      for (int i = first; i < std::min(triangles, first + kTrianglesPerChunk); ++i)
        v.membrane_energy[i] = triangle(capsule_active_[i], v.membrane[i]);
    }
  });
  const int nodes = static_cast<int>(mesh_.V.rows());
  workers_.run(chunks(nodes, kNodesPerChunk), [&](int chunk) {
    const double* tet = v.tet.empty() ? nullptr : v.tet[0].data();
    const double* membrane = v.membrane.empty() ? nullptr : v.membrane[0].data();
    for (int node = chunk * kNodesPerChunk; node < std::min(nodes, (chunk + 1) * kNodesPerChunk); ++node) {
      auto fn = f.segment<3>(3 * node);
      for (int s = v.tet_gather.start[node]; s < v.tet_gather.start[node + 1]; ++s)
        fn += Eigen::Map<const Eigen::Vector3d>(tet + v.tet_gather.slot[s]);
      if (triangles == 0) continue;
      for (int s = v.membrane_gather.start[node]; s < v.membrane_gather.start[node + 1]; ++s)
        fn += Eigen::Map<const Eigen::Vector3d>(membrane + v.membrane_gather.slot[s]);
    }
  });
  double sum = 0;
  for (double e : v.block_energy) sum += e;
  for (int i = 0; i < triangles; ++i) sum += v.membrane_energy[i];
  return sum;
}

void MechanicalModel::internal_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) {
  // The last evaluation is kept: a step starts where the previous one ended, and the energy
  // check looks at the state the line search accepted.
  if (evaluated_at(x)) {
    f = internal_at_;
    return;
  }
  if (capsule_.enabled) {  // the tetrahedra's rotations come with their forces
    const int triangles = membrane_.size();
    workers_.run(chunks(triangles, kTrianglesPerChunk), [&](int chunk) {
      const int first = chunk * kTrianglesPerChunk;
      membrane_.update_rotations(x, first, std::min(kTrianglesPerChunk, triangles - first));
    });
  }
  // The strain energy comes with the forces, at little extra cost.
  tissue_energy_at_ = element_pass(
      x.size(), f, [&](int first, int count, Vector12d* fe) { return tetra_.element_forces(first, count, x, fe); },
      [&](int t, Vector9d& fm) { return membrane_.element_force(t, x, fm); });
  if (!vessels_.empty()) vessels_.add_forces(x, f);
  if (stiffness_scale_ != 1) {
    f *= stiffness_scale_;
    tissue_energy_at_ *= stiffness_scale_;
  }
  rotations_at_ = x;
  internal_at_ = f;
}

double MechanicalModel::elastic_energy(const Eigen::VectorXd& x) {
  internal_forces(x, energy_work_);  // brings every rotation and beam frame to x (often already there)
  double beams = 0;
  for (int e = 0; e < vessels_.num_beams(); ++e) beams += vessels_.beam_energy(e);
  return tissue_energy_at_ + stiffness_scale_ * beams;
}

void MechanicalModel::external_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const {
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

void MechanicalModel::set_surface_targets(std::vector<SurfaceTarget> targets) {
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
  surface_targets_ = std::move(targets);
}

void MechanicalModel::set_surface_loads(Eigen::VectorXd loads) {
  if (loads.size() != 0 && loads.size() != X_.size())
    throw std::invalid_argument("surface loads: " + std::to_string(loads.size()) + " values for " +
                                std::to_string(X_.size()) + " degrees of freedom");
  if (!loads.allFinite()) throw std::invalid_argument("surface loads: a value is not finite");
  surface_loads_ = std::move(loads);
}

double MechanicalModel::spring_stiffness() const {
  double total = 0;
  for (const SurfaceTarget& t : surface_targets_) total += t.stiffness;
  return total;
}

void MechanicalModel::add_target_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const {
  for (const SurfaceTarget& t : surface_targets_) {
    const Eigen::Vector3d pull = -t.stiffness * t.stretch(x, boundary_);
    for (int j = 0; j < 3; ++j) f.segment<3>(3 * boundary_(t.triangle, j)) += t.weights[j] * pull;
  }
  if (surface_loads_.size() != 0) f += surface_loads_;
}

void MechanicalModel::snapshot_damping(const Eigen::VectorXd& x) {
  internal_forces(x, energy_work_);  // brings rotations, frames and hosts to x (usually already there)
  damping_.tet_rotation = tetra_.rotations();
  if (capsule_.enabled) damping_.membrane_frame = membrane_.frames();
  vessels_.snapshot_damping();
}

void MechanicalModel::damping_forces(const Eigen::VectorXd& v, Eigen::VectorXd& f) {
  element_pass(
      v.size(), f,
      [&](int first, int count, Vector12d* fe) {
        tetra_.tangent_products(first, count, damping_.tet_rotation, v, fe);
        return 0.0;
      },
      [&](int t, Vector9d& fm) {
        membrane_.tangent_product(t, damping_.membrane_frame[t], v, fm);
        return 0.0;
      });
  vessels_.add_damping_forces(v, f);
  if (stiffness_scale_ != 1) f *= stiffness_scale_;
}

void MechanicalModel::assemble(double k, double m, std::vector<double>& values) {
  // On one thread: the values a tetrahedron adds overlap its neighbours', and a split whose sums
  // do not depend on the thread count would need the element matrices kept (13 MB on the
  // phantom). It runs when the factor is refreshed, beside a factorisation ten times longer.
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
  vessels_.add_tangent(beam_map_, stiffness_);
  values.resize(stiffness_.size());
  const double tissue = k * stiffness_scale_;
  for (size_t i = 0; i < stiffness_.size(); ++i) values[i] = tissue * stiffness_[i];
  // The targets' springs: external, so undamped; k w w^T (x) P per triangle, P = n n^T
  // (point-to-plane) or I.
  Matrix9d Kt;
  for (const SurfaceTarget& t : surface_targets_) {
    const Eigen::Matrix3d ww = t.stiffness * t.weights * t.weights.transpose();
    const Eigen::Matrix3d P = t.projector();
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) Kt.block<3, 3>(3 * a, 3 * b) = ww(a, b) * P;
    scatter_add(Kt, &tri_map_[81 * t.triangle], values);
  }
  for (int i = 0; i < pattern_.rows(); ++i) {
    values[pattern_.diagonal(i)] += m * mass_[i];
    if (fixed_dof_[i]) values[pattern_.diagonal(i)] = 1.0;
  }
  for (int i : fixed_entries_) values[i] = 0.0;
}

}  // namespace liver_sim
