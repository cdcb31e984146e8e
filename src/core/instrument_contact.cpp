#include "liver_sim/instrument_contact.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "liver_sim/contact_solver.h"

namespace liver_sim {
namespace {

constexpr int kMaxKrylov = 30;  // GMRES iterations per Newton update
constexpr int kMaxStages = 16;  // instrument stages per step

void require_valid(const std::string& message) {
  if (!message.empty()) throw std::invalid_argument(message);
}

const ContactOptions& validated(const ContactOptions& o) {
  require_valid(validate(o));
  return o;
}

}  // namespace

InstrumentContact::InstrumentContact(MechanicalModel& mechanics, const ContactOptions& options)
    : mechanics_(mechanics), options_(validated(options)) {
  const Eigen::Index dofs = mechanics_.rest_positions().size();
  x_stage_ = mechanics_.rest_positions();
  force_.setZero(dofs);
  force_start_.setZero(dofs);
  compliance_slot_.assign(dofs / 3, -1);
}

int InstrumentContact::add_instrument(const InstrumentOptions& o, double time) {
  require_valid(validate(o));
  if (find_instrument(o.name) >= 0) throw std::invalid_argument("instruments." + o.name + ": the name is taken");
  Instrument in;
  in.options = o;
  in.pose = in.pose_start = pose_at(o, time);
  if (o.type == InstrumentOptions::Type::Tube) in.suction_load = mechanics_.add_pressure_load();
  instruments_.push_back(std::move(in));
  return num_instruments() - 1;
}

void InstrumentContact::update_instrument(int i, const InstrumentOptions& o) {
  require_valid(validate(o));
  if (o.type != instruments_[i].options.type || o.name != instruments_[i].options.name)
    throw std::invalid_argument("instruments." + instruments_[i].options.name + ": name and type cannot change");
  instruments_[i].options = o;
}

int InstrumentContact::find_instrument(const std::string& name) const {
  for (int i = 0; i < num_instruments(); ++i)
    if (instruments_[i].options.name == name) return i;
  return -1;
}

void InstrumentContact::reset() {
  contacts_.clear();
  force_.setZero();
  for (Instrument& in : instruments_) {
    in.closed = false;
    in.was_enabled = false;
    in.held.clear();
    in.held_local.clear();
    in.reaction = InstrumentReaction{};
  }
}

int InstrumentContact::begin_step(double t, const Eigen::VectorXd& x) {
  force_start_ = force_;
  const Eigen::MatrixX3i& boundary = mechanics_.boundary();
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
        for (int node : mechanics_.boundary_nodes())
          depth = std::max(depth, -surface_distance(o, in.pose, x.segment<3>(3 * node)).distance);
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
        for (int node : mechanics_.boundary_nodes()) {
          const Eigen::Vector3d p = x.segment<3>(3 * node);
          if (mechanics_.fixed_by_scene(node) || (p - in.pose_start.translation()).norm() > o.radius) continue;
          in.held.push_back(node);
          in.held_local.push_back(in.pose_start.inverse() * p);
        }
      } else if (!closed) {
        in.held.clear();
        in.held_local.clear();
      }
      in.closed = closed;
    }
    if (in.suction_load >= 0) {
      // Suction acts on the surface inside the lumen as the step starts.
      PressureLoad& load = mechanics_.pressure_load(in.suction_load);
      load.pressure = -o.suction;
      load.triangles.clear();
      if (!o.enabled || o.suction == 0) continue;
      for (int f = 0; f < boundary.rows(); ++f) {
        const Eigen::Vector3d a = x.segment<3>(3 * boundary(f, 0)), b = x.segment<3>(3 * boundary(f, 1)),
                              c = x.segment<3>(3 * boundary(f, 2));
        if (in_tube_lumen(o, in.pose, (a + b + c) / 3, (b - a).cross(c - a))) load.triangles.push_back(f);
      }
    }
  }
  stage_from_.clear();
  stage_to_.clear();
  for (const Instrument& in : instruments_) {
    stage_from_.push_back(in.pose_start);
    stage_to_.push_back(in.pose);
  }
  return stages;
}

void InstrumentContact::begin_stage(int k, int stages, const Eigen::VectorXd& x) {
  for (int i = 0; i < num_instruments(); ++i) {
    Instrument& in = instruments_[i];
    in.pose_start = k == 1 ? stage_from_[i] : in.pose;
    const double s = static_cast<double>(k) / stages;
    in.pose = make_pose((1 - s) * stage_from_[i].translation() + s * stage_to_[i].translation(),
                        Eigen::Quaterniond(stage_from_[i].linear()).slerp(s, Eigen::Quaterniond(stage_to_[i].linear())));
  }
  x_stage_ = x;
}

bool InstrumentContact::detect(const Eigen::VectorXd& x) {
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
    for (int node : mechanics_.boundary_nodes()) {
      if (mechanics_.fixed_by_scene(node)) continue;  // the scene holds those already
      if (surface_distance(in.options, in.pose, x.segment<3>(3 * node)).distance >= options_.alarm_distance) continue;
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
    force_.setZero();
    for (const Contact& c : contacts_) force_.segment<3>(3 * c.node) += c.force;
  }
  return dropped_force;
}

Eigen::Vector3d InstrumentContact::contact_rows(int c, const Eigen::VectorXd& x, Eigen::Matrix3d* frame) const {
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

double InstrumentContact::violation(const Eigen::VectorXd& x) const {
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
    const double cone = options_.friction * lambda[0];
    if (lambda[0] > 0 && lambda.tail<2>().norm() < cone * (1 - 1e-6))  // strictly inside: sticks
      worst = std::max(worst, rows.tail<2>().norm());
  }
  return worst;
}

InstrumentContact::Update InstrumentContact::newton_update(CholmodSolver& factor, const Gmres::Operator& jacobian,
                                                           const Eigen::VectorXd& r, double forcing, Eigen::VectorXd& dx) {
  Update update;
  // 1. Compliance columns of the factor now in use: the nodes that lack them, in one solve.
  if (compliance_factor_ != factor.factorizations()) {
    for (int node : compliance_nodes_) compliance_slot_[node] = -1;
    compliance_nodes_.clear();
    compliance_factor_ = factor.factorizations();
  }
  std::vector<int>& missing = missing_nodes_;
  missing.clear();
  for (const Contact& c : contacts_)
    if (compliance_slot_[c.node] < 0 && std::find(missing.begin(), missing.end(), c.node) == missing.end())
      missing.push_back(c.node);
  const Eigen::Index dofs = r.size();
  if (!missing.empty()) {
    rhs_columns_.setZero(dofs, 3 * static_cast<Eigen::Index>(missing.size()));
    for (size_t k = 0; k < missing.size(); ++k)
      for (int d = 0; d < 3; ++d) rhs_columns_(3 * missing[k] + d, 3 * k + d) = 1.0;
    factor.solve(rhs_columns_, new_columns_);
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
  factor.solve(r, free_dx_);
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
    contact_delta_.segment<3>(3 * c) = contact.rows + contact.frame.transpose() * free_dx_.segment<3>(3 * contact.node);
    contact_lambda_.segment<3>(3 * c) = contact.frame.transpose() * contact.force;
    contact_bilateral_[c] = contact.bilateral;
  }
  const ContactSolveResult solved = solve_frictional_contacts(delassus_, contact_delta_, contact_bilateral_, options_.friction,
                                                              0.01 * options_.tolerance, options_.max_iterations, contact_lambda_);
  ++solves_;
  update.sweeps = solved.sweeps;

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
    const double cone = options_.friction * lambda[0];
    if (contact.bilateral || (lambda[0] > 0 && options_.friction > 0 && lambda.tail<2>().norm() < cone * (1 - 1e-9))) {
      for (int k = 0; k < 3; ++k) unknown_rows_.push_back({c, contact.frame.col(k), contact.frame.col(k), -contact.rows[k]});
    } else if (lambda[0] > 0) {
      Eigen::Vector3d direction = contact.frame.col(0);
      if (options_.friction > 0) direction += contact.frame.rightCols<2>() * (lambda.tail<2>() / lambda[0]);
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
  augmented_rhs_.head(dofs) = r - force_;
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
    factor.solve(augmented_dx_, augmented_out_);
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
  update.krylov = gmres_.solve(system, preconditioner, augmented_rhs_, augmented_solution_, forcing, kMaxKrylov);
  update.relative_residual = gmres_.relative_residual();
  dx = augmented_solution_.head(dofs);
  force_.setZero();
  for (Contact& c : contacts_) c.force.setZero();
  for (int a = 0; a < k; ++a) {
    Contact& c = contacts_[unknown_rows_[a].contact];
    c.force += unknown_rows_[a].force * augmented_solution_[dofs + a];
    force_.segment<3>(3 * c.node) += unknown_rows_[a].force * augmented_solution_[dofs + a];
  }
  return update;
}

void InstrumentContact::end_step(bool rolled_back, const Eigen::VectorXd& x) {
  if (rolled_back) {
    force_ = force_start_;
    detect(x);  // the contacts of the restored state (their forces are kept)
  }
  for (Instrument& in : instruments_) in.reaction = InstrumentReaction{};
  for (const Contact& c : contacts_) {
    if (c.force.isZero(0.0)) continue;
    InstrumentReaction& reaction = instruments_[c.instrument].reaction;
    reaction.force -= c.force;
    reaction.torque -= (x.segment<3>(3 * c.node) - instruments_[c.instrument].pose.translation()).cross(c.force);
    ++reaction.contacts;
  }
}

int InstrumentContact::loaded_contacts() const {
  int n = 0;
  for (const Contact& c : contacts_) n += !c.force.isZero(0.0);
  return n;
}

}  // namespace liver_sim
