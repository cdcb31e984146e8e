#include "liver_sim/scene/scene.h"

#include "scene_overrides.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace liver_sim {
namespace {

// Reads one YAML tree into a Scene; every error names the origin and the dotted key.
class Reader {
 public:
  explicit Reader(std::string origin) : origin_(std::move(origin)) {}

  [[noreturn]] void fail(const std::string& key, const std::string& message) const {
    throw SceneError(origin_ + ": " + (key.empty() ? "" : key + ": ") + message);
  }

  void require_valid(const std::string& message) const {
    if (!message.empty()) throw SceneError(origin_ + ": " + message);
  }

  void check_keys(const YAML::Node& node, const std::string& key, const std::set<std::string>& allowed) const {
    if (!node.IsMap()) fail(key, "expected a map");
    for (const auto& kv : node) {
      const std::string name = kv.first.as<std::string>();
      if (!allowed.count(name)) fail("", "unknown key '" + join(key, name) + "'");
    }
  }

  static std::string join(const std::string& key, const std::string& name) {
    return key.empty() ? name : key + "." + name;
  }

  double number(const YAML::Node& node, const std::string& key) const {
    if (!node.IsScalar()) fail(key, "expected a number");
    double v;
    try {
      v = node.as<double>();
    } catch (const YAML::Exception&) {
      fail(key, "expected a number, got '" + node.Scalar() + "'");
    }
    if (!std::isfinite(v)) fail(key, "must be finite");
    return v;
  }

  int integer(const YAML::Node& node, const std::string& key) const {
    if (!node.IsScalar()) fail(key, "expected an integer");
    try {
      return node.as<int>();
    } catch (const YAML::Exception&) {
      fail(key, "expected an integer, got '" + node.Scalar() + "'");
    }
  }

  bool boolean(const YAML::Node& node, const std::string& key) const {
    if (!node.IsScalar()) fail(key, "expected true or false");
    try {
      return node.as<bool>();
    } catch (const YAML::Exception&) {
      fail(key, "expected true or false, got '" + node.Scalar() + "'");
    }
  }

  std::string word(const YAML::Node& node, const std::string& key, const std::set<std::string>& allowed) const {
    const std::string w = node.IsScalar() ? node.Scalar() : "";
    if (!allowed.count(w)) {
      std::string list;
      for (const std::string& a : allowed) list += (list.empty() ? "" : " | ") + a;
      fail(key, "expected " + list + (w.empty() ? "" : ", got '" + w + "'"));
    }
    return w;
  }

  Eigen::Vector3d vec3(const YAML::Node& node, const std::string& key) const {
    if (!node.IsSequence() || node.size() != 3) fail(key, "expected a list of 3 numbers");
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) v[i] = number(node[i], key + "." + std::to_string(i));
    return v;
  }

  const YAML::Node required(const YAML::Node& map, const std::string& key, const std::string& name) const {
    const YAML::Node n = map[name];
    if (!n) fail(join(key, name), "missing");
    return n;
  }

  Region region(const YAML::Node& node, const std::string& key) const {
    check_keys(node, key, {"box", "sphere", "disc"});
    if (node.size() != 1) fail(key, "expected exactly one of box, sphere, disc");
    Region r;
    if (const YAML::Node b = node["box"]) {
      const std::string k = key + ".box";
      check_keys(b, k, {"min", "max"});
      r.kind = Region::Kind::Box;
      r.min = vec3(required(b, k, "min"), k + ".min");
      r.max = vec3(required(b, k, "max"), k + ".max");
    } else if (const YAML::Node s = node["sphere"]) {
      const std::string k = key + ".sphere";
      check_keys(s, k, {"center", "radius"});
      r.kind = Region::Kind::Sphere;
      r.center = vec3(required(s, k, "center"), k + ".center");
      r.radius = number(required(s, k, "radius"), k + ".radius");
    } else {
      const YAML::Node d = node["disc"];
      const std::string k = key + ".disc";
      check_keys(d, k, {"center", "normal", "radius", "inner_radius", "depth"});
      r.kind = Region::Kind::Disc;
      r.center = vec3(required(d, k, "center"), k + ".center");
      r.normal = vec3(required(d, k, "normal"), k + ".normal");
      r.radius = number(required(d, k, "radius"), k + ".radius");
      if (d["inner_radius"]) r.inner_radius = number(d["inner_radius"], k + ".inner_radius");
      if (d["depth"]) r.depth = number(d["depth"], k + ".depth");
    }
    const std::string error = validate(r);
    if (!error.empty()) fail(key, error);
    return r;
  }

  std::vector<InstrumentOptions> instruments(const YAML::Node& list) const {
    if (!list.IsSequence()) fail("instruments", "expected a list of instruments");
    std::set<std::string> names;
    std::vector<InstrumentOptions> out;
    for (size_t i = 0; i < list.size(); ++i) out.push_back(instrument(list[i], "instruments." + std::to_string(i), names));
    return out;
  }

  Scene scene(const YAML::Node& root, const std::string& base_dir) const {
    if (!root.IsMap()) fail("", "expected a map of sections");
    check_keys(root, "", {"mesh", "parenchyma", "capsule", "fixed", "loads", "solver", "probes", "vessels",
                          "instruments", "contact", "registration"});
    Scene s;
    read_mesh_source(required(root, "", "mesh"), base_dir, s.mesh);
    if (const YAML::Node p = root["parenchyma"]) {
      check_keys(p, "parenchyma", {"young_modulus", "poisson_ratio", "density", "rotation"});
      if (p["young_modulus"]) s.parenchyma.young_modulus = number(p["young_modulus"], "parenchyma.young_modulus");
      if (p["poisson_ratio"]) s.parenchyma.poisson_ratio = number(p["poisson_ratio"], "parenchyma.poisson_ratio");
      if (p["density"]) s.parenchyma.density = number(p["density"], "parenchyma.density");
      if (p["rotation"])
        s.parenchyma.rotation = word(p["rotation"], "parenchyma.rotation", {"polar", "geometric"}) == "polar"
                                    ? RotationMethod::Polar
                                    : RotationMethod::Geometric;
    }
    if (const YAML::Node c = root["capsule"]) {
      check_keys(c, "capsule", {"enabled", "young_modulus", "thickness", "poisson_ratio", "region"});
      if (c["enabled"]) s.capsule.enabled = boolean(c["enabled"], "capsule.enabled");
      if (c["young_modulus"]) s.capsule.young_modulus = number(c["young_modulus"], "capsule.young_modulus");
      if (c["thickness"]) s.capsule.thickness = number(c["thickness"], "capsule.thickness");
      if (c["poisson_ratio"]) s.capsule.poisson_ratio = number(c["poisson_ratio"], "capsule.poisson_ratio");
      if (c["region"]) s.capsule.region = region(c["region"], "capsule.region");
    }
    if (const YAML::Node f = root["fixed"]) {
      if (!f.IsSequence()) fail("fixed", "expected a list of regions");
      for (size_t i = 0; i < f.size(); ++i) s.fixed.push_back(region(f[i], "fixed." + std::to_string(i)));
    }
    if (const YAML::Node l = root["loads"]) {
      if (!l.IsSequence()) fail("loads", "expected a list of loads");
      for (size_t i = 0; i < l.size(); ++i) s.loads.push_back(load(l[i], "loads." + std::to_string(i)));
    }
    if (const YAML::Node v = root["solver"]) read_solver(v, s.solver);
    if (const YAML::Node p = root["probes"]) {
      if (!p.IsSequence()) fail("probes", "expected a list of probes");
      std::set<std::string> names;
      for (size_t i = 0; i < p.size(); ++i) {
        const std::string k = "probes." + std::to_string(i);
        check_keys(p[i], k, {"name", "point"});
        ProbeOptions probe;
        probe.name = required(p[i], k, "name").as<std::string>();
        if (probe.name.empty() || !names.insert(probe.name).second)
          fail(k + ".name", "probe names must be non-empty and unique");
        probe.point = vec3(required(p[i], k, "point"), k + ".point");
        s.probes.push_back(probe);
      }
    }
    if (const YAML::Node v = root["vessels"]) {
      if (!v.IsSequence()) fail("vessels", "expected a list of vessel trees");
      std::set<std::string> names;
      for (size_t i = 0; i < v.size(); ++i) s.vessels.push_back(vessel(v[i], "vessels." + std::to_string(i), base_dir, names));
    }
    if (const YAML::Node in = root["instruments"]) s.instruments = instruments(in);
    if (const YAML::Node c = root["contact"]) {
      check_keys(c, "contact", {"friction", "alarm_distance", "tolerance", "max_iterations"});
      if (c["friction"]) s.contact.friction = number(c["friction"], "contact.friction");
      if (c["alarm_distance"]) s.contact.alarm_distance = number(c["alarm_distance"], "contact.alarm_distance");
      if (c["tolerance"]) s.contact.tolerance = number(c["tolerance"], "contact.tolerance");
      if (c["max_iterations"]) s.contact.max_iterations = integer(c["max_iterations"], "contact.max_iterations");
    }
    if (const YAML::Node g = root["registration"]) read_registration(g, s.registration);
    require_valid(validate(s.parenchyma));
    require_valid(validate(s.capsule));
    require_valid(validate(s.solver));
    require_valid(validate(s.contact));
    require_valid(validate(s.registration));
    return s;
  }

 private:
  SolverOptions::Strategy strategy(const YAML::Node& n, const std::string& key) const {
    return *parse_strategy(
        word(n, key, {"newton_krylov", "full_newton", "full_newton_eigen", "reused_factor_cg", "cg", "modified_newton"}));
  }

  void read_registration(const YAML::Node& g, RegistrationOptions& o) const {
    check_keys(g, "registration", {"stiffness", "metric", "voxel_size", "max_points", "max_distance", "trim_fraction",
                                   "huber_width", "correspondence_updates", "frame_updates", "newton_iterations", "strategy",
                                   "rigid_alignment", "min_points", "min_coverage", "full_coverage",
                                   "candidate_supports", "support_stiffness", "support_gain", "min_tissue_stiffness_factor", "max_tissue_stiffness_factor",
                                   "estimate_hidden_loads", "hidden_load_damping", "uncertainty"});
    if (g["strategy"]) o.strategy = strategy(g["strategy"], "registration.strategy");
    if (g["newton_iterations"]) o.newton_iterations = integer(g["newton_iterations"], "registration.newton_iterations");
    if (g["stiffness"]) o.stiffness = number(g["stiffness"], "registration.stiffness");
    if (g["metric"])
      o.metric = word(g["metric"], "registration.metric", {"point_to_plane", "point_to_point"}) == "point_to_plane"
                     ? RegistrationOptions::Metric::PointToPlane
                     : RegistrationOptions::Metric::PointToPoint;
    if (g["voxel_size"]) o.voxel_size = number(g["voxel_size"], "registration.voxel_size");
    if (g["max_points"]) o.max_points = integer(g["max_points"], "registration.max_points");
    if (g["max_distance"]) o.max_distance = number(g["max_distance"], "registration.max_distance");
    if (g["trim_fraction"]) o.trim_fraction = number(g["trim_fraction"], "registration.trim_fraction");
    if (g["huber_width"]) o.huber_width = number(g["huber_width"], "registration.huber_width");
    if (g["correspondence_updates"])
      o.correspondence_updates = integer(g["correspondence_updates"], "registration.correspondence_updates");
    if (g["frame_updates"]) o.frame_updates = integer(g["frame_updates"], "registration.frame_updates");
    if (g["rigid_alignment"]) o.rigid_alignment = boolean(g["rigid_alignment"], "registration.rigid_alignment");
    if (g["min_points"]) o.min_points = integer(g["min_points"], "registration.min_points");
    if (g["min_coverage"]) o.min_coverage = number(g["min_coverage"], "registration.min_coverage");
    if (g["full_coverage"]) o.full_coverage = number(g["full_coverage"], "registration.full_coverage");
    if (const YAML::Node c = g["candidate_supports"]) {
      if (!c.IsSequence()) fail("registration.candidate_supports", "expected a list of regions");
      for (size_t i = 0; i < c.size(); ++i)
        o.candidate_supports.push_back(region(c[i], "registration.candidate_supports." + std::to_string(i)));
    }
    if (g["support_stiffness"]) o.support_stiffness = number(g["support_stiffness"], "registration.support_stiffness");
    if (g["support_gain"]) o.support_gain = number(g["support_gain"], "registration.support_gain");
    if (g["min_tissue_stiffness_factor"])
      o.min_tissue_stiffness_factor = number(g["min_tissue_stiffness_factor"], "registration.min_tissue_stiffness_factor");
    if (g["max_tissue_stiffness_factor"])
      o.max_tissue_stiffness_factor = number(g["max_tissue_stiffness_factor"], "registration.max_tissue_stiffness_factor");
    if (g["estimate_hidden_loads"])
      o.estimate_hidden_loads = boolean(g["estimate_hidden_loads"], "registration.estimate_hidden_loads");
    if (g["hidden_load_damping"]) o.hidden_load_damping = number(g["hidden_load_damping"], "registration.hidden_load_damping");
    if (const YAML::Node u = g["uncertainty"]) {
      check_keys(u, "registration.uncertainty", {"patch_spacing", "force_ratio", "stiffness_log_sd"});
      UncertaintyOptions& q = o.uncertainty;
      if (u["patch_spacing"]) q.patch_spacing = number(u["patch_spacing"], "registration.uncertainty.patch_spacing");
      if (u["force_ratio"]) q.force_ratio = number(u["force_ratio"], "registration.uncertainty.force_ratio");
      if (u["stiffness_log_sd"]) q.stiffness_log_sd = number(u["stiffness_log_sd"], "registration.uncertainty.stiffness_log_sd");
    }
  }

  void read_mesh_source(const YAML::Node& m, const std::string& base_dir, MeshSource& out) const {
    check_keys(m, "mesh", {"file", "scale", "box"});
    if (static_cast<bool>(m["file"]) == static_cast<bool>(m["box"]))
      fail("mesh", "expected exactly one of file, box");
    if (const YAML::Node f = m["file"]) {
      if (!f.IsScalar() || f.Scalar().empty()) fail("mesh.file", "expected a path");
      out.file = resolve(base_dir, f.Scalar());
      if (m["scale"]) {
        out.scale = number(m["scale"], "mesh.scale");
        if (out.scale <= 0) fail("mesh.scale", "must be > 0");
      }
      return;
    }
    if (m["scale"]) fail("mesh.scale", "only with mesh.file");
    const YAML::Node b = m["box"];
    check_keys(b, "mesh.box", {"size", "divisions"});
    out.box_size = vec3(required(b, "mesh.box", "size"), "mesh.box.size");
    if ((out.box_size.array() <= 0).any()) fail("mesh.box.size", "must be three positive lengths");
    const YAML::Node d = required(b, "mesh.box", "divisions");
    if (!d.IsSequence() || d.size() != 3) fail("mesh.box.divisions", "expected a list of 3 integers");
    for (int i = 0; i < 3; ++i) {
      out.box_divisions[i] = integer(d[i], "mesh.box.divisions." + std::to_string(i));
      if (out.box_divisions[i] < 1) fail("mesh.box.divisions", "must be >= 1");
    }
  }

  static std::string resolve(const std::string& base_dir, const std::string& file) {
    const std::filesystem::path p(file);
    return p.is_absolute() ? p.string() : (std::filesystem::path(base_dir) / p).string();
  }

  VesselOptions vessel(const YAML::Node& node, const std::string& key, const std::string& base_dir,
                       std::set<std::string>& names) const {
    check_keys(node, key, {"name", "file", "scale", "enabled", "young_modulus", "poisson_ratio", "snap_tolerance"});
    VesselOptions o;
    const YAML::Node name = required(node, key, "name");
    if (!name.IsScalar() || name.Scalar().empty() || !names.insert(name.Scalar()).second)
      fail(key + ".name", "vessel names must be non-empty and unique");
    o.name = name.Scalar();
    const YAML::Node file = required(node, key, "file");
    if (!file.IsScalar() || file.Scalar().empty()) fail(key + ".file", "expected a path");
    o.file = resolve(base_dir, file.Scalar());
    if (node["scale"]) o.scale = number(node["scale"], key + ".scale");
    if (node["enabled"]) o.enabled = boolean(node["enabled"], key + ".enabled");
    if (node["young_modulus"]) o.young_modulus = number(node["young_modulus"], key + ".young_modulus");
    if (node["poisson_ratio"]) o.poisson_ratio = number(node["poisson_ratio"], key + ".poisson_ratio");
    if (node["snap_tolerance"]) o.snap_tolerance = number(node["snap_tolerance"], key + ".snap_tolerance");
    const std::string error = validate(o);
    if (!error.empty()) fail(key, error);
    return o;
  }

  Eigen::Quaterniond quaternion(const YAML::Node& node, const std::string& key) const {
    if (!node.IsSequence() || node.size() != 4) fail(key, "expected [x, y, z, w]");
    Eigen::Quaterniond q(number(node[3], key + ".3"), number(node[0], key + ".0"), number(node[1], key + ".1"),
                         number(node[2], key + ".2"));
    if (q.norm() < 1e-6) fail(key, "the quaternion must be non-zero");
    return q.normalized();
  }

  // {position: [x, y, z], orientation: [x, y, z, w]} (orientation optional: identity).
  void pose(const YAML::Node& node, const std::string& key, Eigen::Vector3d& p, Eigen::Quaterniond& q) const {
    check_keys(node, key, {"position", "orientation"});
    p = vec3(required(node, key, "position"), key + ".position");
    if (node["orientation"]) q = quaternion(node["orientation"], key + ".orientation");
  }

  InstrumentOptions instrument(const YAML::Node& node, const std::string& key, std::set<std::string>& names) const {
    if (!node.IsMap()) fail(key, "expected a map");
    const std::string type = word(required(node, key, "type"), key + ".type", {"probe", "shaft", "tube", "grasper"});
    std::set<std::string> allowed = {"name", "type", "enabled", "pose", "trajectory"};
    using Type = InstrumentOptions::Type;
    InstrumentOptions o;
    if (type == "probe") {
      o.type = Type::Probe;
      allowed.insert("radius");
    } else if (type == "shaft") {
      o.type = Type::Shaft;
      allowed.insert({"radius", "length"});
    } else if (type == "tube") {
      o.type = Type::Tube;
      allowed.insert({"inner_radius", "outer_radius", "length", "suction"});
    } else {
      o.type = Type::Grasper;
      allowed.insert({"radius", "closed"});
    }
    check_keys(node, key, allowed);
    const YAML::Node name = required(node, key, "name");
    if (!name.IsScalar() || name.Scalar().empty() || !names.insert(name.Scalar()).second)
      fail(key + ".name", "instrument names must be non-empty and unique");
    o.name = name.Scalar();
    if (node["enabled"]) o.enabled = boolean(node["enabled"], key + ".enabled");
    if (node["radius"]) o.radius = number(node["radius"], key + ".radius");
    if (node["length"]) o.length = number(node["length"], key + ".length");
    if (node["inner_radius"]) o.inner_radius = number(node["inner_radius"], key + ".inner_radius");
    if (node["outer_radius"]) o.outer_radius = number(node["outer_radius"], key + ".outer_radius");
    if (node["suction"]) o.suction = number(node["suction"], key + ".suction");
    if (node["closed"]) o.closed = boolean(node["closed"], key + ".closed");
    if (node["pose"]) pose(node["pose"], key + ".pose", o.position, o.orientation);
    if (const YAML::Node path = node["trajectory"]) {
      if (!path.IsSequence() || path.size() == 0) fail(key + ".trajectory", "expected a list of {t, position, orientation}");
      for (size_t i = 0; i < path.size(); ++i) {
        const std::string k = key + ".trajectory." + std::to_string(i);
        check_keys(path[i], k, {"t", "position", "orientation", "closed"});
        InstrumentOptions::Keyframe f;
        f.t = number(required(path[i], k, "t"), k + ".t");
        f.position = vec3(required(path[i], k, "position"), k + ".position");
        if (path[i]["orientation"]) f.orientation = quaternion(path[i]["orientation"], k + ".orientation");
        if (path[i]["closed"]) {
          if (o.type != Type::Grasper) fail(k + ".closed", "only a grasper opens and closes");
          f.closed = boolean(path[i]["closed"], k + ".closed");
        }
        o.trajectory.push_back(f);
      }
    }
    if (!node["pose"] && !node["trajectory"]) fail(key, "needs a pose or a trajectory");
    const std::string error = validate(o);
    if (!error.empty()) fail(key, error);
    return o;
  }

  LoadOptions load(const YAML::Node& node, const std::string& key) const {
    if (!node.IsMap()) fail(key, "expected a map");
    const std::string type = word(required(node, key, "type"), key + ".type", {"pressure", "gravity", "force"});
    LoadOptions l;
    if (type == "pressure") {
      check_keys(node, key, {"type", "value", "region"});
      l.kind = LoadOptions::Kind::Pressure;
      l.pressure = number(required(node, key, "value"), key + ".value");
      if (node["region"]) l.region = region(node["region"], key + ".region");
    } else if (type == "gravity") {
      check_keys(node, key, {"type", "acceleration"});
      l = LoadOptions::gravity(vec3(required(node, key, "acceleration"), key + ".acceleration"));
    } else {
      check_keys(node, key, {"type", "total", "region"});
      l.kind = LoadOptions::Kind::Force;
      l.vector = vec3(required(node, key, "total"), key + ".total");
      l.region = region(required(node, key, "region"), key + ".region");
    }
    return l;
  }

  void read_solver(const YAML::Node& v, SolverOptions& o) const {
    check_keys(v, "solver", {"mode", "strategy", "predictor", "dt", "steps", "max_iterations", "tolerance",
                             "line_search", "rayleigh_mass", "rayleigh_stiffness", "threads", "time_budget",
                             "capped_residual", "background_refresh"});
    if (v["strategy"]) o.strategy = strategy(v["strategy"], "solver.strategy");
    if (v["predictor"]) {
      const std::string p = word(v["predictor"], "solver.predictor", {"none", "constant_velocity", "constant_acceleration"});
      o.predictor = p == "none"                ? SolverOptions::Predictor::None
                    : p == "constant_velocity" ? SolverOptions::Predictor::ConstantVelocity
                                               : SolverOptions::Predictor::ConstantAcceleration;
    }
    if (v["mode"])
      o.mode = word(v["mode"], "solver.mode", {"static", "dynamic"}) == "static" ? SolverOptions::Mode::Static
                                                                                : SolverOptions::Mode::Dynamic;
    if (v["dt"]) o.dt = number(v["dt"], "solver.dt");
    if (v["steps"]) o.steps = integer(v["steps"], "solver.steps");
    if (v["max_iterations"]) o.max_iterations = integer(v["max_iterations"], "solver.max_iterations");
    if (v["tolerance"]) o.tolerance = number(v["tolerance"], "solver.tolerance");
    if (v["line_search"]) o.line_search = boolean(v["line_search"], "solver.line_search");
    if (v["rayleigh_mass"]) o.rayleigh_mass = number(v["rayleigh_mass"], "solver.rayleigh_mass");
    if (v["rayleigh_stiffness"]) o.rayleigh_stiffness = number(v["rayleigh_stiffness"], "solver.rayleigh_stiffness");
    if (v["threads"]) o.threads = integer(v["threads"], "solver.threads");
    if (v["time_budget"]) o.time_budget = number(v["time_budget"], "solver.time_budget");
    if (v["capped_residual"]) o.capped_residual = number(v["capped_residual"], "solver.capped_residual");
    if (v["background_refresh"]) o.background_refresh = boolean(v["background_refresh"], "solver.background_refresh");
  }

  std::string origin_;
};

}  // namespace

Scene parse_scene(const std::string& yaml, const std::string& base_dir, const std::string& origin,
                  const std::vector<std::string>& overrides) {
  const Reader reader(origin);
  // yaml-cpp recurses once per nesting level: bound what reaches it (scenes are small and flat).
  if (yaml.size() > (1u << 20)) reader.fail("", "larger than 1 MiB");
  int depth = 0;
  for (char c : yaml) {
    depth = std::max(0, depth + (c == '[' || c == '{') - (c == ']' || c == '}'));
    if (depth > 32) reader.fail("", "nested deeper than 32 levels");
  }
  YAML::Node root;
  try {
    root = YAML::Load(yaml);
  } catch (const YAML::Exception& e) {
    reader.fail("", std::string("YAML syntax: ") + e.what());
  }
  if (!root.IsDefined() || root.IsNull()) reader.fail("", "empty scene");
  apply_overrides(root, overrides, origin);
  try {
    return reader.scene(root, base_dir);
  } catch (const YAML::Exception& e) {
    reader.fail("", e.what());
  }
}

std::string read_scene_text(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw SceneError(path + ": cannot open");
  std::stringstream text;
  text << in.rdbuf();
  // yaml-cpp recurses once per nesting level: bound what reaches it (scene files are small).
  if (text.str().size() > (1u << 20)) throw SceneError(path + ": larger than 1 MiB");
  return text.str();
}

std::vector<InstrumentOptions> load_instruments(const std::string& path) {
  const Reader reader(path);
  const std::string text = read_scene_text(path);
  try {
    const YAML::Node root = YAML::Load(text);
    if (!root.IsMap()) reader.fail("", "expected a map with an instruments list");
    reader.check_keys(root, "", {"instruments"});
    return reader.instruments(reader.required(root, "", "instruments"));
  } catch (const YAML::Exception& e) {
    reader.fail("", std::string("YAML syntax: ") + e.what());
  }
}

Scene load_scene(const std::string& path, const std::vector<std::string>& overrides) {
  const std::string dir = std::filesystem::absolute(path).parent_path().string();
  return parse_scene(read_scene_text(path), dir, path, overrides);
}

}  // namespace liver_sim
