#include "liver_sim/contact/instrument_contact.h"

#include <algorithm>
#include <limits>
#include <cmath>
#include <stdexcept>

#include "liver_sim/contact/contact_solver.h"

namespace liver_sim {
namespace {

constexpr int kMaxKrylov = 30;  // GMRES iterations per Newton update
constexpr int kMaxStages = 16;  // instrument stages per step
constexpr int kMaxRetreats = 32;  // steps back along the axis of an instrument that appears

void require_valid(const std::string& message) {
  if (!message.empty()) throw std::invalid_argument(message);
}

const ContactOptions& validated(const ContactOptions& o) {
  require_valid(validate(o));
  return o;
}

}  // namespace

Eigen::Vector3d SurfacePoint::at(const Eigen::VectorXd& x) const {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int j = 0; j < count; ++j) p += weights[j] * x.segment<3>(3 * nodes[j]);
  return p;
}

SurfacePoint SurfacePoint::on_triangle(const Eigen::Vector3i& nodes, const Eigen::Vector3d& w) {
  SurfacePoint p;
  double sum = 0;
  for (int k = 0; k < 3; ++k) {
    if (w[k] <= 1e-9) continue;
    // Insertion in node order.
    int j = p.count++;
    for (; j > 0 && p.nodes[j - 1] > nodes[k]; --j) {
      p.nodes[j] = p.nodes[j - 1];
      p.weights[j] = p.weights[j - 1];
    }
    p.nodes[j] = nodes[k];
    p.weights[j] = w[k];
    sum += w[k];
  }
  p.weights /= sum;
  return p;
}

InstrumentContact::InstrumentContact(MechanicalModel& mechanics, const ContactOptions& options)
    : mechanics_(mechanics),
      options_(validated(options)),
      compliance_(static_cast<int>(mechanics.rest_positions().size() / 3)) {
  const Eigen::Index dofs = mechanics_.rest_positions().size();
  x_stage_ = mechanics_.rest_positions();
  node_vector_.assign(dofs / 3, Eigen::Vector3d::Zero());
  node_marked_.assign(dofs / 3, 0);
}

int InstrumentContact::add_instrument(const InstrumentOptions& o, double time) {
  require_valid(validate(o));
  if (find_instrument(o.name) >= 0) throw std::invalid_argument("instruments." + o.name + ": the name is taken");
  if (num_instruments() >= kMaxInstruments)
    throw std::invalid_argument("instruments." + o.name + ": at most " + std::to_string(kMaxInstruments) +
                                " instruments in a model");
  Instrument in;  // placed, then listed: a failure (memory) leaves the list as it was
  place(in, o, time);
  instruments_.push_back(std::move(in));
  return num_instruments() - 1;
}

void InstrumentContact::replace_instrument(int i, const InstrumentOptions& o, double time) {
  require_valid(validate(o));
  const int named = find_instrument(o.name);
  if (named >= 0 && named != i) throw std::invalid_argument("instruments." + o.name + ": the name is taken");
  Instrument& in = instruments_.at(i);
  // Out of the scene at the last step: the detection kept no contact of it.
  if (!withdrawn(i)) throw std::invalid_argument("instruments." + in.options.name + ": in the scene, not replaced");
  const int suction_load = in.suction_load;  // a former tube's load stays with the slot (begin_step: no pressure unless a tube)
  in = Instrument();
  in.suction_load = suction_load;
  place(in, o, time);
}

void InstrumentContact::place(Instrument& in, const InstrumentOptions& o, double time) {
  in.options = o;
  in.pose = in.pose_start = pose_at(o, time);
  if (o.type == InstrumentOptions::Type::Tube && in.suction_load < 0) in.suction_load = mechanics_.add_pressure_load();
}

void InstrumentContact::update_instrument(int i, const InstrumentOptions& o) {
  require_valid(validate(o));
  Instrument& in = instruments_.at(i);
  if (o.type != in.options.type || o.name != in.options.name)
    throw std::invalid_argument("instruments." + in.options.name + ": name and type cannot change");
  in.options = o;
}

std::string InstrumentContact::set_options(const ContactOptions& o) {
  const std::string error = validate(o);
  if (error.empty()) options_ = o;
  return error;
}

int InstrumentContact::find_instrument(const std::string& name) const {
  for (int i = 0; i < num_instruments(); ++i)
    if (instruments_[i].options.name == name) return i;
  return -1;
}

void InstrumentContact::reset() {
  contacts_.clear();
  for (Instrument& in : instruments_) {
    in.closed = false;
    in.was_enabled = false;
    in.held.clear();
    in.held_local.clear();
    in.reaction = InstrumentReaction{};
  }
}

double InstrumentContact::size(const InstrumentOptions& o) {
  return o.type == InstrumentOptions::Type::Tube ? o.outer_radius - o.inner_radius : o.radius;
}

template <typename Visit>
void InstrumentContact::near_triangles(const InstrumentOptions& o, const Eigen::Isometry3d& pose, const Eigen::VectorXd& x,
                                       double reach, const Visit& visit) const {
  const Eigen::MatrixX3i& boundary = mechanics_.boundary();
  for (int t = 0; t < boundary.rows(); ++t) {
    const Eigen::Vector3d a = x.segment<3>(3 * boundary(t, 0)), b = x.segment<3>(3 * boundary(t, 1)),
                          c = x.segment<3>(3 * boundary(t, 2));
    const Eigen::Vector3d centre = (a + b + c) / 3;
    const double radius = std::sqrt(std::max({(a - centre).squaredNorm(), (b - centre).squaredNorm(), (c - centre).squaredNorm()}));
    if (surface_distance(o, pose, centre).distance - radius >= reach) continue;
    visit(t, a, b, c);
  }
}

template <typename Visit>
void InstrumentContact::sample_triangle(int t, double spacing, const Visit& visit) const {
  const Eigen::MatrixX3i& boundary = mechanics_.boundary();
  const Eigen::VectorXd& X = mechanics_.rest_positions();
  std::array<int, 3> v = {boundary(t, 0), boundary(t, 1), boundary(t, 2)};
  std::sort(v.begin(), v.end());
  // Divisions of each edge (shared with the neighbour across it: the same rest length) and of
  // the triangle (its longest edge's).
  const auto divisions = [&](int a, int b) {
    const double length = (X.segment<3>(3 * a) - X.segment<3>(3 * b)).norm();
    return std::isfinite(spacing) ? std::max(1, static_cast<int>(std::ceil(length / spacing))) : 1;
  };
  const int edge_divisions[3] = {divisions(v[0], v[1]), divisions(v[1], v[2]), divisions(v[0], v[2])};
  SurfacePoint s;
  for (int j = 0; j < 3; ++j) {
    s.nodes = {v[j], -1, -1};
    s.weights = Eigen::Vector3d(1, 0, 0);
    s.count = 1;
    s.sample = 0;
    visit(s);
  }
  const int ends[3][2] = {{0, 1}, {1, 2}, {0, 2}};
  for (int e = 0; e < 3; ++e)
    for (int i = 1; i < edge_divisions[e]; ++i) {
      const double w = static_cast<double>(i) / edge_divisions[e];
      s.nodes = {v[ends[e][0]], v[ends[e][1]], -1};
      s.weights = Eigen::Vector3d(1 - w, w, 0);
      s.count = 2;
      s.sample = i;
      visit(s);
    }
  const int n = *std::max_element(edge_divisions, edge_divisions + 3);
  s.nodes = v;
  s.count = 3;
  for (int i = 1; i < n; ++i)
    for (int j = 1; i + j < n; ++j) {
      s.weights = Eigen::Vector3d(n - i - j, i, j) / n;
      s.sample = i * n + j;
      visit(s);
    }
}

void InstrumentContact::save(State& s) const {
  s.instruments = instruments_;
  s.contacts = contacts_;
  s.suction.clear();
  for (const Instrument& in : instruments_)
    if (in.suction_load >= 0) s.suction.push_back(mechanics_.pressure_load(in.suction_load));
  s.x_stage = x_stage_;
  s.stage_from = stage_from_;
  s.stage_to = stage_to_;
}

void InstrumentContact::restore(const State& s) {
  instruments_ = s.instruments;
  contacts_ = s.contacts;
  size_t k = 0;
  for (const Instrument& in : instruments_)
    if (in.suction_load >= 0) mechanics_.pressure_load(in.suction_load) = s.suction[k++];
  x_stage_ = s.x_stage;
  stage_from_ = s.stage_from;
  stage_to_ = s.stage_to;
}

int InstrumentContact::begin_step(double t, const Eigen::VectorXd& x) {
  const Eigen::MatrixX3i& boundary = mechanics_.boundary();
  int stages = 1;
  for (int k = 0; k < num_instruments(); ++k) {
    Instrument& in = instruments_[k];
    const InstrumentOptions& o = in.options;
    in.pose_start = in.pose;
    in.pose = pose_at(o, t);
    if (o.enabled && o.type != InstrumentOptions::Type::Grasper) {
      if (!in.was_enabled) {
        // It appears: it comes in along its axis from where it touches the surface nowhere. Each
        // retreat by the deepest penetration brings that closer (for a rod through the surface,
        // by its radius at a time until its tip is out).
        in.pose_start = in.pose;
        for (int retreat = 0; retreat < kMaxRetreats; ++retreat) {
          double depth = 0;
          near_triangles(o, in.pose_start, x, 0.0, [&](int, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
            depth = std::max(depth, -deepest_point(o, in.pose_start, a, b, c).distance.distance);
          });
          if (depth <= 0) break;
          in.pose_start.translation() += depth * in.pose.linear().col(2);
        }
      }
      // In floating point until capped: the travel may be any finite length (the cast of a
      // value beyond int's range is undefined). A shaft or a tube turned travels farthest at
      // one of its ends.
      double travel = (in.pose.translation() - in.pose_start.translation()).norm();
      if (o.type == InstrumentOptions::Type::Shaft || o.type == InstrumentOptions::Type::Tube) {
        const Eigen::Vector3d far_end(0, 0, o.length);
        travel = std::max(travel, (in.pose * far_end - in.pose_start * far_end).norm());
      }
      stages = std::max(stages, static_cast<int>(std::min<double>(kMaxStages, std::ceil(travel / (0.25 * size(o))))));
    }
    in.was_enabled = o.enabled;
    if (o.type == InstrumentOptions::Type::Grasper) {
      const bool closed = o.enabled && closed_at(o, t);
      if (closed && !in.closed) {
        // The jaws close on the surface nodes within reach, where they are at this instant; on
        // the nearest surface point when they reach no node.
        const Eigen::Vector3d tip = in.pose_start.translation();
        for (int node : mechanics_.boundary_nodes()) {
          if (mechanics_.fixed_by_scene(node) || (x.segment<3>(3 * node) - tip).norm() > o.radius) continue;
          in.held.push_back(SurfacePoint::on_triangle(Eigen::Vector3i(node, node, node), Eigen::Vector3d(1, 0, 0)));
        }
        if (in.held.empty()) {
          double nearest = o.radius;
          for (int f = 0; f < boundary.rows(); ++f) {
            const Eigen::Vector3d a = x.segment<3>(3 * boundary(f, 0)), b = x.segment<3>(3 * boundary(f, 1)),
                                  c = x.segment<3>(3 * boundary(f, 2));
            const TrianglePoint p = deepest_point(o, in.pose_start, a, b, c);
            const SurfacePoint s = SurfacePoint::on_triangle(boundary.row(f).transpose(), p.weights);
            const double distance = (s.at(x) - tip).norm();
            // As for contacts (detect): a point held at least half by the supports is theirs.
            double supported = 0;
            for (int j = 0; j < s.count; ++j) supported += mechanics_.fixed_by_scene(s.nodes[j]) ? s.weights[j] : 0.0;
            if (!(distance <= nearest) || !(supported < 0.5)) continue;
            nearest = distance;
            in.held.assign(1, s);
          }
        }
        for (const SurfacePoint& s : in.held) in.held_local.push_back(in.pose_start.inverse() * s.at(x));
      } else if (!closed) {
        in.held.clear();
        in.held_local.clear();
      }
      in.closed = closed;
    }
    if (in.suction_load >= 0) {
      // Suction acts on the surface inside the lumen as the step starts.
      PressureLoad& load = mechanics_.pressure_load(in.suction_load);
      const bool tube = o.type == InstrumentOptions::Type::Tube;  // a slot that held a tube keeps its load
      load.pressure = tube ? -o.suction : 0.0;
      load.triangles.clear();
      if (!o.enabled || load.pressure == 0) continue;
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
  // Contacts are listed by instrument, then surface point: the previous forces are matched in
  // one pass, and a point found from two triangles (on their edge or node) is kept once.
  const auto less = [](const Contact& a, const Contact& b) {
    if (a.instrument != b.instrument) return a.instrument < b.instrument;
    return a.point.nodes != b.point.nodes ? a.point.nodes < b.point.nodes : a.point.sample < b.point.sample;
  };
  const auto same = [](const Contact& a, const Contact& b) {
    return a.instrument == b.instrument && a.point.nodes == b.point.nodes && a.point.sample == b.point.sample;
  };
  contacts_next_.clear();
  long samples = 0;
  for (int k = 0; k < num_instruments(); ++k) {
    const Instrument& in = instruments_[k];
    if (!in.options.enabled) continue;
    const size_t first = contacts_next_.size();
    if (in.options.type == InstrumentOptions::Type::Grasper) {
      for (size_t h = 0; h < in.held.size(); ++h)
        contacts_next_.push_back({k, in.held[h], static_cast<int>(h), Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(),
                                  Eigen::Vector3d::Zero()});
    } else {
      // Samples of the near triangles, at most half the instrument's radius of curvature apart
      // (in the rest shape): a curved tip then sinks between them by at most 1/32 of that
      // radius. Against a large instrument the nodes alone; a flat tube rim touches the
      // surface at its nodes.
      const double spacing = in.options.type == InstrumentOptions::Type::Tube ? std::numeric_limits<double>::infinity()
                                                                               : 0.5 * in.options.radius;
      near_triangles(in.options, in.pose, x, options_.alarm_distance,
                     [&](int t, const Eigen::Vector3d&, const Eigen::Vector3d&, const Eigen::Vector3d&) {
                       sample_triangle(t, spacing, [&](const SurfacePoint& s) {
                         if (++samples > kMaxContactSamples)
                           throw std::length_error("more than " + std::to_string(kMaxContactSamples) +
                                                   " surface samples near instruments." + in.options.name +
                                                   " (half its radius apart): too thin for the mesh, or the alarm distance too large");
                         // A point held at least half by the scene's supports is left to them:
                         // its free nodes alone could push it out only by moving twice as far or
                         // more (an instrument pressing on a support pinches the tissue there).
                         double held = 0;
                         for (int j = 0; j < s.count; ++j) held += mechanics_.fixed_by_scene(s.nodes[j]) ? s.weights[j] : 0.0;
                         if (held < 0.5 && surface_distance(in.options, in.pose, s.at(x)).distance < options_.alarm_distance)
                           contacts_next_.push_back({k, s, -1, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(),
                                                     Eigen::Vector3d::Zero()});
                       });
                     });
    }
    std::sort(contacts_next_.begin() + first, contacts_next_.end(), less);
    contacts_next_.erase(std::unique(contacts_next_.begin() + first, contacts_next_.end(), same), contacts_next_.end());
  }
  // Refused before the Delassus operator is sized for them: the step rolls back and the model
  // keeps its state until the instruments move or change.
  if (contacts_next_.size() > static_cast<size_t>(kMaxContacts)) {
    std::vector<int> per_instrument(num_instruments(), 0);
    for (const Contact& c : contacts_next_) ++per_instrument[c.instrument];
    const int k = static_cast<int>(std::max_element(per_instrument.begin(), per_instrument.end()) - per_instrument.begin());
    throw std::length_error(std::to_string(contacts_next_.size()) + " contact points, at most " +
                            std::to_string(kMaxContacts) + " of all instruments (the most: instruments." +
                            instruments_[k].options.name + ", " + std::to_string(per_instrument[k]) + ")");
  }
  bool dropped_force = false;
  size_t j = 0;
  for (Contact& c : contacts_next_) {
    for (; j < contacts_.size() && less(contacts_[j], c); ++j) dropped_force |= !contacts_[j].lambda.isZero(0.0);
    if (j < contacts_.size() && same(contacts_[j], c)) c.lambda = contacts_[j++].lambda;
  }
  for (; j < contacts_.size(); ++j) dropped_force |= !contacts_[j].lambda.isZero(0.0);
  contacts_.swap(contacts_next_);
  for (Contact& c : contacts_) c.rows = contact_rows(c, x, &c.frame);
  return dropped_force;
}

Eigen::Vector3d InstrumentContact::contact_rows(const Contact& c, const Eigen::VectorXd& x, Eigen::Matrix3d* frame) const {
  const Instrument& in = instruments_[c.instrument];
  const Eigen::Vector3d p = c.point.at(x);
  if (c.held >= 0) {
    frame->setIdentity();
    return p - in.pose * in.held_local[c.held];
  }
  const SurfaceDistance d = surface_distance(in.options, in.pose, p);
  // Tangents: any orthonormal pair (forces are carried between iterations in the world frame).
  const Eigen::Vector3d helper = std::abs(d.normal.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d t1 = d.normal.cross(helper).normalized();
  frame->col(0) = d.normal;
  frame->col(1) = t1;
  frame->col(2) = d.normal.cross(t1);
  // Slip over the step: against the instrument point that was under the surface point at its start.
  const Eigen::Vector3d slip = p - in.pose * (in.pose_start.inverse() * c.point.at(x_stage_));
  return Eigen::Vector3d(d.distance, frame->col(1).dot(slip), frame->col(2).dot(slip));
}

bool InstrumentContact::deep(const Eigen::VectorXd& x) const {
  for (const Contact& c : contacts_) {
    if (c.held >= 0) continue;
    const Instrument& in = instruments_[c.instrument];
    if (surface_distance(in.options, in.pose, c.point.at(x)).distance < -0.25 * size(in.options)) return true;
  }
  return false;
}

double InstrumentContact::violation(const Eigen::VectorXd& x) const {
  double worst = 0;
  Eigen::Matrix3d frame;
  for (const Contact& contact : contacts_) {
    const Eigen::Vector3d rows = contact_rows(contact, x, &frame);
    if (contact.held >= 0) {
      worst = std::max(worst, rows.cwiseAbs().maxCoeff());
      continue;
    }
    const Eigen::Vector3d& lambda = contact.lambda;
    worst = std::max(worst, lambda[0] > 0 ? std::abs(rows[0]) : -rows[0]);  // Signorini
    if (!(lambda[0] > 0 && options_.friction > 0)) continue;
    // Coulomb, measured continuously in the force: a slip counts in full at the cone's centre
    // (sticking), not at all on its edge (sliding), and a slip along the friction force on the
    // tissue, which must oppose it, counts too.
    const double cone = options_.friction * lambda[0];
    const Eigen::Vector2d tangential = lambda.tail<2>(), slip = rows.tail<2>();
    const double friction = tangential.norm();
    worst = std::max(worst, std::clamp(1 - friction / cone, 0.0, 1.0) * slip.norm());
    if (friction > 0) worst = std::max(worst, slip.dot(tangential) / friction);
  }
  return worst;
}

void InstrumentContact::contact_problem(CholmodSolver& factor, const Eigen::VectorXd& r) {
  lambda_before_update_.resize(contacts_.size());
  for (size_t c = 0; c < contacts_.size(); ++c) lambda_before_update_[c] = contacts_[c].lambda;
  free_nodes_.clear();
  try {
    for (const Contact& c : contacts_)
      for (int j = 0; j < c.point.count; ++j) {
        const int node = c.point.nodes[j];
        if (mechanics_.fixed_by_scene(node) || node_marked_[node]) continue;
        free_nodes_.push_back(node);
        node_marked_[node] = 1;
      }
  } catch (...) {  // memory: no mark may outlive the list (a marked node is never listed again)
    for (int node : free_nodes_) node_marked_[node] = 0;
    throw;
  }
  for (int node : free_nodes_) node_marked_[node] = 0;
  compliance_.require(free_nodes_, factor);
  factor.forward(r, z_);
  for (int node : free_nodes_) node_vector_[node] = compliance_.dot(node, z_);
  const int m = static_cast<int>(contacts_.size());
  W_.resize(3 * m, 3 * m);
  delta_.resize(3 * m);
  lambda_.resize(3 * m);
  bilateral_.resize(m);
  for (int c = 0; c < m; ++c) {
    const Contact& a = contacts_[c];
    Eigen::Vector3d predicted = Eigen::Vector3d::Zero();  // H A^-1 r at the point
    for (int j = 0; j < a.point.count; ++j)
      if (!mechanics_.fixed_by_scene(a.point.nodes[j])) predicted += a.point.weights[j] * node_vector_[a.point.nodes[j]];
    delta_.segment<3>(3 * c) = a.rows + a.frame.transpose() * predicted;
    lambda_.segment<3>(3 * c) = a.lambda;
    bilateral_[c] = a.held >= 0;
    for (int d = c; d < m; ++d) {
      const Contact& b = contacts_[d];
      Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
      for (int j = 0; j < a.point.count; ++j) {
        if (mechanics_.fixed_by_scene(a.point.nodes[j])) continue;
        for (int k = 0; k < b.point.count; ++k)
          if (!mechanics_.fixed_by_scene(b.point.nodes[k]))
            G += (a.point.weights[j] * b.point.weights[k]) * compliance_.block(a.point.nodes[j], b.point.nodes[k]);
      }
      W_.block<3, 3>(3 * c, 3 * d) = a.frame.transpose() * G * b.frame;
      W_.block<3, 3>(3 * d, 3 * c) = W_.block<3, 3>(3 * c, 3 * d).transpose();
    }
  }
}

void InstrumentContact::add_forward(const std::vector<Eigen::Vector3d>& change) {
  for (int node : free_nodes_) node_vector_[node].setZero();
  for (size_t c = 0; c < contacts_.size(); ++c) {
    const SurfacePoint& p = contacts_[c].point;
    for (int j = 0; j < p.count; ++j)
      if (!mechanics_.fixed_by_scene(p.nodes[j])) node_vector_[p.nodes[j]] += p.weights[j] * change[c];
  }
  for (int node : free_nodes_) compliance_.add(node, node_vector_[node], z_);
}

double InstrumentContact::gap_tolerance(double force_tolerance) const {
  // A gap left open by e carries a force error of about e / W_cc.
  double compliance = std::numeric_limits<double>::infinity();
  for (Eigen::Index c = 0; c < W_.rows(); c += 3) compliance = std::min(compliance, W_(c, c));
  return std::min(0.01 * options_.tolerance, force_tolerance * compliance);
}

int InstrumentContact::solve_contact_problem(CholmodSolver& factor, const Eigen::VectorXd& r, double force_tolerance) {
  contact_problem(factor, r);
  const ContactSolveResult solved = solve_frictional_contacts(W_, delta_, bilateral_, options_.friction,
                                                              gap_tolerance(force_tolerance), options_.max_iterations, lambda_);
  ++solves_;
  return solved.sweeps;
}

InstrumentContact::Update InstrumentContact::direct_update(CholmodSolver& factor, const Eigen::VectorXd& r,
                                                           double force_tolerance, Eigen::VectorXd& dx) {
  Update update;
  update.sweeps = solve_contact_problem(factor, r, force_tolerance);
  change_.resize(contacts_.size());
  for (size_t c = 0; c < contacts_.size(); ++c) {
    change_[c] = contacts_[c].frame * (lambda_.segment<3>(3 * c) - contacts_[c].lambda);
    contacts_[c].lambda = lambda_.segment<3>(3 * c);
  }
  add_forward(change_);
  factor.backward(z_, dx);
  keep_update();
  return update;
}

InstrumentContact::Update InstrumentContact::krylov_update(CholmodSolver& factor, const Gmres::Operator& jacobian,
                                                           const Eigen::VectorXd& r, double forcing, double force_tolerance,
                                                           Eigen::VectorXd& dx) {
  Update update;
  // 1. The frictional contact problem with the rows predicted after the tangent's update A^-1 r:
  // which contacts separate, stick or slide.
  update.sweeps = solve_contact_problem(factor, r, force_tolerance);

  // 2. The Newton update for that contact state, on the true Jacobian J:
  //      J dx - B lambda = r_free,   H dx = -rows
  // (sticking and held contacts: three rows and forces along the frame; sliding: the normal
  // row, and a force along n + mu t on the cone's edge; separating: none). GMRES, preconditioned
  // by the same system with the tangent A: lambda = S^-1 (g - H A^-1 u), dx = A^-1 (u + B lambda),
  // S = H A^-1 B, each application one forward and one backward half solve.
  unknowns_.clear();
  const int m = static_cast<int>(contacts_.size());
  for (int c = 0; c < m; ++c) {
    const Contact& contact = contacts_[c];
    const Eigen::Vector3d lambda = lambda_.segment<3>(3 * c);
    const double cone = options_.friction * lambda[0];
    if (contact.held >= 0 || (lambda[0] > 0 && options_.friction > 0 && lambda.tail<2>().norm() < cone * (1 - 1e-9))) {
      for (int k = 0; k < 3; ++k) unknowns_.push_back({c, contact.frame.col(k), contact.frame.col(k), -contact.rows[k]});
    } else if (lambda[0] > 0) {
      Eigen::Vector3d direction = contact.frame.col(0);
      if (options_.friction > 0) direction += contact.frame.rightCols<2>() * (lambda.tail<2>() / lambda[0]);
      unknowns_.push_back({c, contact.frame.col(0), direction, -contact.rows[0]});
    }
  }
  const int k = static_cast<int>(unknowns_.size());
  const std::vector<char>& fixed = mechanics_.fixed_dofs();
  // The point's motion or force through its free nodes.
  const auto point_of = [&](const SurfacePoint& p, const Eigen::VectorXd& v) {
    Eigen::Vector3d s = Eigen::Vector3d::Zero();
    for (int j = 0; j < p.count; ++j)
      if (!mechanics_.fixed_by_scene(p.nodes[j])) s += p.weights[j] * v.segment<3>(3 * p.nodes[j]);
    return s;
  };
  schur_.resize(k, k);
  for (int a = 0; a < k; ++a) {
    const SurfacePoint& pa = contacts_[unknowns_[a].contact].point;
    for (int b = 0; b < k; ++b) {
      const SurfacePoint& pb = contacts_[unknowns_[b].contact].point;
      Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
      for (int i = 0; i < pa.count; ++i) {
        if (mechanics_.fixed_by_scene(pa.nodes[i])) continue;
        for (int j = 0; j < pb.count; ++j)
          if (!mechanics_.fixed_by_scene(pb.nodes[j]))
            G += (pa.weights[i] * pb.weights[j]) * compliance_.block(pa.nodes[i], pb.nodes[j]);
      }
      schur_(a, b) = unknowns_[a].row.dot(G * unknowns_[b].force);
    }
  }
  schur_solver_.setThreshold(1e-10);
  if (k > 0) schur_solver_.compute(schur_);  // (Eigen's decomposition fails on an empty matrix)
  const Eigen::Index dofs = r.size();
  augmented_rhs_.resize(dofs + k);
  augmented_rhs_.head(dofs) = r;
  for (const Contact& c : contacts_) {  // the free forces: r without the contact forces
    const Eigen::Vector3d force = c.frame * c.lambda;
    for (int j = 0; j < c.point.count; ++j) augmented_rhs_.segment<3>(3 * c.point.nodes[j]) -= c.point.weights[j] * force;
  }
  for (Eigen::Index i = 0; i < dofs; ++i)
    if (fixed[i]) augmented_rhs_[i] = 0;
  for (int a = 0; a < k; ++a) augmented_rhs_[dofs + a] = unknowns_[a].target;
  const Gmres::Operator system = [&](const Eigen::VectorXd& z, Eigen::VectorXd& out) {
    augmented_dx_ = z.head(dofs);
    jacobian(augmented_dx_, augmented_out_);
    out.resize(dofs + k);
    out.head(dofs) = augmented_out_;
    for (int a = 0; a < k; ++a) {
      const SurfacePoint& p = contacts_[unknowns_[a].contact].point;
      for (int j = 0; j < p.count; ++j)
        if (!mechanics_.fixed_by_scene(p.nodes[j]))
          out.segment<3>(3 * p.nodes[j]) -= p.weights[j] * unknowns_[a].force * z[dofs + a];
      out[dofs + a] = unknowns_[a].row.dot(point_of(p, z));
    }
  };
  const Gmres::Operator preconditioner = [&](const Eigen::VectorXd& in, Eigen::VectorXd& out) {
    augmented_dx_ = in.head(dofs);
    factor.forward(augmented_dx_, z_);
    for (int node : free_nodes_) node_vector_[node] = compliance_.dot(node, z_);
    schur_rhs_.resize(k);
    for (int a = 0; a < k; ++a) {
      const SurfacePoint& p = contacts_[unknowns_[a].contact].point;
      Eigen::Vector3d predicted = Eigen::Vector3d::Zero();
      for (int j = 0; j < p.count; ++j)
        if (!mechanics_.fixed_by_scene(p.nodes[j])) predicted += p.weights[j] * node_vector_[p.nodes[j]];
      schur_rhs_[a] = in[dofs + a] - unknowns_[a].row.dot(predicted);
    }
    schur_solution_ = k > 0 ? Eigen::VectorXd(schur_solver_.solve(schur_rhs_)) : Eigen::VectorXd();
    change_.assign(contacts_.size(), Eigen::Vector3d::Zero());
    for (int a = 0; a < k; ++a) change_[unknowns_[a].contact] += unknowns_[a].force * schur_solution_[a];
    add_forward(change_);
    factor.backward(z_, augmented_out_);
    out.resize(dofs + k);
    out.head(dofs) = augmented_out_;
    out.tail(k) = schur_solution_;
  };
  update.krylov = gmres_.solve(system, preconditioner, augmented_rhs_, augmented_solution_, forcing, kMaxKrylov);
  update.relative_residual = gmres_.relative_residual();
  dx = augmented_solution_.head(dofs);
  change_.assign(contacts_.size(), Eigen::Vector3d::Zero());
  for (int a = 0; a < k; ++a) change_[unknowns_[a].contact] += unknowns_[a].force * augmented_solution_[dofs + a];
  for (size_t c = 0; c < contacts_.size(); ++c) contacts_[c].lambda = contacts_[c].frame.transpose() * change_[c];
  keep_update();
  return update;
}

void InstrumentContact::add_forces(const Eigen::VectorXd& x, Eigen::VectorXd& f) const {
  Eigen::Matrix3d frame;
  for (const Contact& c : contacts_) {
    if (c.lambda.isZero(0.0)) continue;
    contact_rows(c, x, &frame);  // the force turns with the instrument's surface at the point
    const Eigen::Vector3d force = frame * c.lambda;
    for (int n = 0; n < c.point.count; ++n) f.segment<3>(3 * c.point.nodes[n]) += c.point.weights[n] * force;
  }
}

Eigen::VectorXd InstrumentContact::forces(const Eigen::VectorXd& x) const {
  Eigen::VectorXd f = Eigen::VectorXd::Zero(x.size());
  add_forces(x, f);
  return f;
}

void InstrumentContact::keep_update() {
  lambda_of_update_.resize(contacts_.size());
  for (size_t c = 0; c < contacts_.size(); ++c) lambda_of_update_[c] = contacts_[c].lambda;
}

void InstrumentContact::scale_update(double alpha) {
  for (size_t c = 0; c < contacts_.size(); ++c)
    contacts_[c].lambda = lambda_before_update_[c] + alpha * (lambda_of_update_[c] - lambda_before_update_[c]);
}

bool InstrumentContact::add_force_change(Eigen::VectorXd& f) const {
  bool changed = false;
  for (size_t c = 0; c < contacts_.size(); ++c) {
    const Contact& contact = contacts_[c];
    const Eigen::Vector3d change = contact.frame * (lambda_of_update_[c] - lambda_before_update_[c]);
    changed |= !change.isZero(0.0);
    for (int n = 0; n < contact.point.count; ++n) f.segment<3>(3 * contact.point.nodes[n]) += contact.point.weights[n] * change;
  }
  return changed;
}

void InstrumentContact::end_step(const Eigen::VectorXd& x) {
  for (Instrument& in : instruments_) in.reaction = InstrumentReaction{};
  for (const Contact& c : contacts_) {
    if (c.lambda.isZero(0.0)) continue;
    InstrumentReaction& reaction = instruments_[c.instrument].reaction;
    const Eigen::Vector3d force = c.frame * c.lambda;
    reaction.force -= force;
    reaction.torque -= (c.point.at(x) - instruments_[c.instrument].pose.translation()).cross(force);
    ++reaction.contacts;
  }
}

int InstrumentContact::loaded_contacts() const {
  int n = 0;
  for (const Contact& c : contacts_) n += !c.lambda.isZero(0.0);
  return n;
}

}  // namespace liver_sim
