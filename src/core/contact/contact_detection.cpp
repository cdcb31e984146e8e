// The contacts of InstrumentContact (instrument_contact.h): their detection at the surface
// samples near each instrument and at the points it holds, and their conditions at a state.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "liver_sim/contact/instrument_contact.h"
#include "liver_sim/contact/instrument_shape.h"
#include "surface_samples.h"

namespace liver_sim {
namespace {

// Contacts are listed by instrument, then surface point: the previous forces are matched in
// one pass, and a point found from two triangles (on their edge or node) is kept once.
bool listed_before(const SurfaceContact& a, const SurfaceContact& b) {
  if (a.instrument != b.instrument) return a.instrument < b.instrument;
  return a.point.nodes != b.point.nodes ? a.point.nodes < b.point.nodes : a.point.sample < b.point.sample;
}

bool same_point(const SurfaceContact& a, const SurfaceContact& b) {
  return a.instrument == b.instrument && a.point.nodes == b.point.nodes && a.point.sample == b.point.sample;
}

}  // namespace

bool InstrumentContact::detect(const Eigen::VectorXd& x) {
  contacts_next_.clear();
  long samples = 0;
  for (int k = 0; k < num_instruments(); ++k) {
    const InstrumentSlot& in = instruments_[k];
    if (!in.options.enabled) continue;
    const size_t first = contacts_next_.size();
    // The points it holds (a closed grasper's): bilateral.
    for (size_t h = 0; h < in.held.size(); ++h)
      contacts_next_.push_back({k, in.held[h], static_cast<int>(h), Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(),
                                Eigen::Vector3d::Zero()});
    const InstrumentShape& shape = shape_of(in.options.type);
    if (shape.pushes()) {
      // Samples of the near triangles, at most the shape's spacing apart (in the rest shape).
      const double spacing = shape.sample_spacing(in.options);
      near_triangles(mechanics_.boundary(), in.options, in.pose, x, options_.alarm_distance,
                     [&](int t, const Eigen::Vector3d&, const Eigen::Vector3d&, const Eigen::Vector3d&) {
                       sample_triangle(mechanics_.boundary(), mechanics_.rest_positions(), t, spacing, [&](const SurfacePoint& s) {
                         if (++samples > kMaxContactSamples)
                           throw std::length_error("more than " + std::to_string(kMaxContactSamples) +
                                                   " surface samples near instruments." + in.options.name +
                                                   " (half its radius apart): too thin for the mesh, or the alarm distance too large");
                         // A point held at least half by the scene's supports is left to them:
                         // its free nodes alone could push it out only by moving twice as far or
                         // more (an instrument pressing on a support pinches the tissue there).
                         double held = 0;
                         for (int j = 0; j < s.count; ++j) held += mechanics_.fixed_by_scene(s.nodes[j]) ? s.weights[j] : 0.0;
                         if (held < 0.5 && shape.distance(in.options, in.pose, s.at(x)).distance < options_.alarm_distance)
                           contacts_next_.push_back({k, s, -1, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(),
                                                     Eigen::Vector3d::Zero()});
                       });
                     });
    }
    std::sort(contacts_next_.begin() + first, contacts_next_.end(), listed_before);
    contacts_next_.erase(std::unique(contacts_next_.begin() + first, contacts_next_.end(), same_point), contacts_next_.end());
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
    for (; j < contacts_.size() && listed_before(contacts_[j], c); ++j) dropped_force |= !contacts_[j].lambda.isZero(0.0);
    if (j < contacts_.size() && same_point(contacts_[j], c)) c.lambda = contacts_[j++].lambda;
  }
  for (; j < contacts_.size(); ++j) dropped_force |= !contacts_[j].lambda.isZero(0.0);
  contacts_.swap(contacts_next_);
  for (Contact& c : contacts_) c.rows = contact_rows(c, instruments_[c.instrument], x, x_stage_, &c.frame);
  return dropped_force;
}

bool InstrumentContact::deep(const Eigen::VectorXd& x) const {
  for (const Contact& c : contacts_) {
    if (c.held >= 0) continue;
    const InstrumentSlot& in = instruments_[c.instrument];
    const InstrumentShape& shape = shape_of(in.options.type);
    if (shape.distance(in.options, in.pose, c.point.at(x)).distance < -0.25 * shape.size(in.options)) return true;
  }
  return false;
}

double InstrumentContact::violation(const Eigen::VectorXd& x) const {
  double worst = 0;
  Eigen::Matrix3d frame;
  for (const Contact& contact : contacts_) {
    const Eigen::Vector3d rows = contact_rows(contact, instruments_[contact.instrument], x, x_stage_, &frame);
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

}  // namespace liver_sim
