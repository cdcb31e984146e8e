#include "bench_press_sweep.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <set>
#include <stdexcept>

#include "liver_sim/geometry/mesh.h"
#include "liver_sim/geometry/node_positions.h"
#include "liver_sim/scene/scene.h"

namespace liver_sim::bench {
namespace {

double scalar(const YAML::Node& n, const std::string& where, const std::string& key) {
  double v = NAN;
  try {
    if (n && n.IsScalar()) v = n.as<double>();
  } catch (const YAML::Exception&) {  // not a number: said below
  }
  if (!std::isfinite(v)) throw std::runtime_error(where + key + ": a finite number is required");
  return v;
}

double number(const YAML::Node& map, const std::string& key, const std::string& where) {
  return scalar(map[key], where, key);
}

std::pair<double, double> pair(const YAML::Node& map, const std::string& key, const std::string& where) {
  const YAML::Node n = map[key];
  if (!n || !n.IsSequence() || n.size() != 2) throw std::runtime_error(where + key + ": two numbers are required");
  return {scalar(n[0], where, key), scalar(n[1], where, key)};
}

void check(bool ok, const std::string& where, const std::string& what) {
  if (!ok) throw std::runtime_error(where + what);
}

}  // namespace

std::optional<PressSweep> read_press_sweep(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::Load(read_scene_text(path));
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
  if (!root.IsMap() || !root["press_sweep"]) return std::nullopt;
  const std::string where = path + ": press_sweep.";
  const YAML::Node m = root["press_sweep"];
  check(m.IsMap() && root.size() == 1, path + ": ", "press_sweep must be the file's only key, a map");
  const std::set<std::string> keys{"name", "type", "radius", "length", "above", "depth", "sweep", "period", "rate",
                                   "duration"};
  try {
    for (const auto& kv : m)
      check(keys.count(kv.first.as<std::string>()) > 0, where, kv.first.as<std::string>() + ": unknown key");
    PressSweep p;
    p.instrument.name = m["name"] ? m["name"].as<std::string>() : "probe";
    const std::string type = m["type"] ? m["type"].as<std::string>() : "probe";
    check(type == "probe" || type == "shaft", where, "type: probe or shaft");
    p.instrument.type = type == "shaft" ? InstrumentOptions::Type::Shaft : InstrumentOptions::Type::Probe;
    p.instrument.radius = number(m, "radius", where);
    if (m["length"]) p.instrument.length = number(m, "length", where);
    const auto [x, y] = pair(m, "above", where);
    p.above = {x, y};
    std::tie(p.depth_min, p.depth_max) = pair(m, "depth", where);
    check(0 <= p.depth_min && p.depth_min <= p.depth_max && p.depth_max <= 0.05, where,
          "depth: [min, max] m with 0 <= min <= max <= 0.05");
    p.sweep = number(m, "sweep", where);
    check(p.sweep >= 0 && p.sweep <= 0.1, where, "sweep: in [0, 0.1] m");
    p.period = number(m, "period", where);
    check(p.period > 0, where, "period: > 0 s");
    p.rate = number(m, "rate", where);
    check(p.rate > 0 && p.rate <= 1000, where, "rate: in (0, 1000] Hz");
    p.duration = number(m, "duration", where);
    check(p.duration > 0 && p.duration * p.rate < 10000, where, "duration: > 0 s, under 10000 keyframes");
    // The scene's own bounds on an instrument (radius, length, name).
    const std::string refused = validate(p.instrument);
    check(refused.empty(), where, refused);
    return p;
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(where + " " + e.what());
  }
}

double surface_height(const Eigen::MatrixX4i& T, const Eigen::VectorXd& x, const Eigen::Vector2d& xy) {
  const Eigen::MatrixX3i triangles = boundary_triangles(T);
  double height = -INFINITY;
  for (int t = 0; t < triangles.rows(); ++t) {
    const Eigen::Vector3d a = node(x, triangles(t, 0)), b = node(x, triangles(t, 1)), c = node(x, triangles(t, 2));
    // Barycentric coordinates of xy in the triangle's shadow on the x-y plane.
    const Eigen::Vector2d e1 = (b - a).head<2>(), e2 = (c - a).head<2>(), r = xy - a.head<2>();
    const double det = e1.x() * e2.y() - e1.y() * e2.x();
    if (std::abs(det) <= 1e-15) continue;  // seen edge-on from above
    const double u = (r.x() * e2.y() - r.y() * e2.x()) / det, v = (e1.x() * r.y() - e1.y() * r.x()) / det;
    if (u < 0 || v < 0 || u + v > 1) continue;
    height = std::max(height, (1 - u - v) * a.z() + u * b.z() + v * c.z());
  }
  if (!std::isfinite(height))
    throw std::runtime_error("no surface above (" + std::to_string(xy.x()) + ", " + std::to_string(xy.y()) + ") m");
  return height;
}

InstrumentOptions press_sweep_instrument(const PressSweep& p, double surface) {
  InstrumentOptions o = p.instrument;
  const int frames = static_cast<int>(std::floor(p.duration * p.rate));
  for (int k = 0; k <= frames; ++k) {
    InstrumentOptions::Keyframe f;
    f.t = k / p.rate;
    const double phase = 2 * M_PI * f.t / p.period;
    const double depth = p.depth_min + (p.depth_max - p.depth_min) * (0.5 - 0.5 * std::cos(phase));
    // The tip is the centre of the rounded end: its lowest point lies a radius below it.
    f.position = {p.above.x() + 0.5 * p.sweep * std::sin(0.5 * phase), p.above.y(), surface + o.radius - depth};
    o.trajectory.push_back(f);
  }
  o.position = o.trajectory.front().position;
  return o;
}

}  // namespace liver_sim::bench
