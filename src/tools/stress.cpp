// Numerical stress matrix: the aspiration cube pushed to extreme parameters, time steps, loads
// and meshes, instruments in extreme contact on the probe cube, and steps of each instrument type
// made to fail (the stepper's test hook). Each case has an expected outcome: converged (static:
// within 10 steps; dynamic: every step), or detected as diverging (or throwing) for a stated
// reason and rolled back to the exact state before the step, every observable value to the last
// bit (LiverModel::observable_state), with nothing non-finite left in the model.
//   stress [--quick] [--group NAME] [--set K=V]... [--scene FILE] [--csv FILE]
// (--group: the cases of one group, e.g. contact; --set: a scene override applied to every case
// after its own, e.g. solver.strategy=full_newton; --scene: the default scene's replacement)
// Prints a Markdown table on standard output, progress on standard error. Exit status 0 when
// every case ended as expected, 1 otherwise, 2 on a bad command line.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iostream>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "liver_sim/simulation/liver_model.h"
#include "package_files.h"
#include "tool_io.h"

namespace {

using namespace liver_sim;

// The contact cases' scenes, found beside the tool at run time (package_files.h).
constexpr const char* kProbeScene = "config/scenes/probe_cube.yaml";
constexpr const char* kTubeScene = "config/scenes/aspiration_tube.yaml";

// Outcomes: "converged", or the reason a step was rolled back, the start of its message
// ("stalled", "residual blow-up", "energy growth", ...).
constexpr const char* kConverged = "converged";
constexpr const char* kStalled = "stalled";
constexpr const char* kException = "exception";  // the step threw (an injected fault)

struct Case {
  std::string group, name;
  std::vector<std::string> overrides;             // on the scene (default: the aspiration cube)
  std::function<TetMesh(const Scene&)> mesh;      // default: the scene's
  std::function<void(LiverModel&)> prepare;       // e.g. an inverted start
  int steps = 1;                                  // dynamic: time steps
  bool quick = false;                             // part of the reduced run in the tests
  // The outcomes it may end in: one, or two where the Newton path is chaotic (a tangle of
  // inverted elements, full steps without line search) and rounding, e.g. the thread count,
  // decides between them.
  std::vector<std::string> expected = {kConverged};
  std::string scene = {};                         // empty: the default scene
  std::vector<InstrumentOptions> instruments = {};  // added to the scene's
  // A fault injected into step `fault_step` (1-based; 0: none) through the stepper's test hook.
  NewtonStepper::InjectedFault fault = NewtonStepper::InjectedFault::None;
  int fault_step = 0;
};

struct Outcome {
  std::string result;  // converged | detected | not converged | FAILED
  std::string reason;  // converged, or the rollback's reason
  std::string detail;
  int steps = 0, newton = 0, factorizations = 0, contacts = 0;  // contacts: the most in one step
  double residual = 0, max_u = 0, ms = 0;
  int inverted_start = 0, inverted_end = 0;
  double min_quality = 0;
};

int count_inverted(const LiverModel& m) {
  TetMesh current{m.mesh().V, m.mesh().T};
  const Eigen::VectorXd& x = m.positions();
  for (int i = 0; i < current.V.rows(); ++i) current.V.row(i) = x.segment<3>(3 * i).transpose();
  return static_cast<int>(check_mesh(current).inverted.size());
}

// Shape quality 6 sqrt(2) V / l_max^3: 1 for a regular tetrahedron, 0 for a flat one.
double min_quality(const TetMesh& mesh) {
  double q = 1;
  for (int t = 0; t < mesh.T.rows(); ++t) {
    double l = 0;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) l = std::max(l, (mesh.V.row(mesh.T(t, a)) - mesh.V.row(mesh.T(t, b))).norm());
    q = std::min(q, 6 * std::sqrt(2.0) * signed_volume(mesh.V, mesh.T, t) / (l * l * l));
  }
  return q;
}

// Interior nodes moved randomly by up to `amplitude` x the grid spacing; a move that would make
// an element inverted or flatter than `floor` is halved until it does not.
TetMesh perturbed_box(const Scene& s, double amplitude, double floor) {
  TetMesh mesh = make_box_mesh(s.mesh.box_size, s.mesh.box_divisions);
  const double h = s.mesh.box_size[0] / s.mesh.box_divisions[0];
  std::vector<std::vector<int>> incident(mesh.V.rows());
  for (int t = 0; t < mesh.T.rows(); ++t)
    for (int k = 0; k < 4; ++k) incident[mesh.T(t, k)].push_back(t);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  const Eigen::Vector3d lo = mesh.V.colwise().minCoeff(), hi = mesh.V.colwise().maxCoeff();
  for (int i = 0; i < mesh.V.rows(); ++i) {
    const Eigen::Vector3d p = mesh.V.row(i).transpose();
    if (((p - lo).array() < 1e-12).any() || ((hi - p).array() < 1e-12).any()) continue;
    Eigen::Vector3d d(u(rng), u(rng), u(rng));
    d *= amplitude * h / d.norm();
    for (int tries = 0; tries < 8; ++tries, d *= 0.5) {
      mesh.V.row(i) = (p + d).transpose();
      bool ok = true;
      for (int t : incident[i]) {
        double l = 0;
        for (int a = 0; a < 4; ++a)
          for (int b = a + 1; b < 4; ++b) l = std::max(l, (mesh.V.row(mesh.T(t, a)) - mesh.V.row(mesh.T(t, b))).norm());
        ok &= signed_volume(mesh.V, mesh.T, t) > floor * l * l * l;
      }
      if (ok) break;
      mesh.V.row(i) = p.transpose();
    }
  }
  return mesh;
}

// Folds the part of the body above z = plane down through that plane, squashed to half its
// height: the elements there are inverted (F = diag(1, 1, -1/2)); the solver must unfold them
// or report.
std::function<void(LiverModel&)> fold_above(double plane) {
  return [plane](LiverModel& m) {
    Eigen::VectorXd x = m.positions();
    for (int i = 2; i < x.size(); i += 3)
      if (x[i] > plane) x[i] = plane - 0.5 * (x[i] - plane);
    m.set_positions(x);
  };
}

Outcome run(const Case& c, const std::string& scene_path) {
  Outcome o;
  Scene scene = load_scene(c.scene.empty() ? scene_path : c.scene, c.overrides);
  scene.instruments.insert(scene.instruments.end(), c.instruments.begin(), c.instruments.end());
  TetMesh mesh;
  try {
    mesh = c.mesh ? c.mesh(scene) : load_scene_mesh(scene);
    validate_mesh(mesh, "mesh");
  } catch (const MeshError& e) {
    o.result = "refused";
    o.detail = e.what();
    return o;
  }
  o.min_quality = min_quality(mesh);
  LiverModel m(std::move(mesh), scene);
  if (c.prepare) c.prepare(m);
  o.inverted_start = count_inverted(m);
  const bool dynamic = scene.solver.mode == SolverOptions::Mode::Dynamic;
  // Static: more steps while one ends at the iteration cap closer to equilibrium (the next
  // continues from there), at most 10 (500 Newton iterations).
  const int budget = dynamic ? c.steps : 10;
  const auto t0 = std::chrono::steady_clock::now();
  o.result = "FAILED";
  for (int k = 0; k < budget; ++k) {
    const std::vector<double> before = m.observable_state();
    if (k + 1 == c.fault_step) m.stepper().inject_fault(c.fault);
    StepResult r;
    try {
      r = m.step();
    } catch (const std::exception& e) {
      ++o.steps;
      const bool restored = same_bits(m.observable_state(), before);
      o.result = restored ? "detected" : "FAILED";
      o.reason = kException;
      o.detail = std::string("step ") + std::to_string(k + 1) + " threw: " + e.what() +
                 (restored ? ", rolled back bitwise" : ", NOT rolled back bitwise");
      break;
    }
    ++o.steps;
    o.newton += r.iterations;
    o.factorizations += r.factorizations;
    o.residual = r.residual;
    o.contacts = std::max(o.contacts, r.contacts);
    bool finite = m.positions().allFinite();
    for (int i = 0; i < m.num_instruments(); ++i)
      finite &= m.instrument_reaction(i).force.allFinite() && m.instrument_reaction(i).torque.allFinite();
    if (!finite) {
      o.detail = "non-finite state after a step";
      break;
    }
    if (r.status == StepResult::Status::Diverged) {
      const bool restored = same_bits(m.observable_state(), before);
      o.result = restored ? "detected" : "FAILED";
      o.reason = r.message.substr(0, r.message.find(':'));
      o.detail = r.message + (restored ? ", rolled back bitwise" : ", NOT rolled back bitwise");
      break;
    }
    if (r.converged()) {
      o.result = o.reason = kConverged;
      o.detail.clear();
      if (!dynamic) break;
      continue;
    }
    // Static: the next step continues from a capped one. Dynamic: every step must converge.
    o.result = o.reason = "not converged";
    o.detail = "step " + std::to_string(k + 1) + ": " + r.message;
    if (dynamic) break;
  }
  o.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  o.max_u = m.max_displacement();
  o.inverted_end = count_inverted(m);
  return o;
}

// An instrument `name` of `type` and `radius` (m) along keyframes (s, tip position in mm).
InstrumentOptions instrument(const std::string& name, InstrumentOptions::Type type, double radius,
                             std::vector<std::pair<double, Eigen::Vector3d>> path) {
  InstrumentOptions o;
  o.name = name;
  o.type = type;
  o.radius = radius;
  for (const auto& [t, mm] : path) {
    InstrumentOptions::Keyframe k;
    k.t = t;
    k.position = 1e-3 * mm;
    o.trajectory.push_back(k);
  }
  o.position = o.trajectory.front().position;
  return o;
}

// Extreme contact on the probe cube (15 mm, bottom fixed, friction 0.3), dynamic at 1 ms:
// every step must converge, to 1e-6 (the benchmark's converged contact dynamics: Newton-Krylov
// with contacts stagnates between 1e-7 and 1e-8, doc/contact.md).
void contact_cases(std::vector<Case>& v) {
  using Type = InstrumentOptions::Type;
  using V3 = Eigen::Vector3d;
  const std::string cube = tool::package_file(kProbeScene);
  const std::vector<std::string> dynamic = {"solver.mode=dynamic", "solver.dt=0.001", "solver.tolerance=1e-6"};
  auto add = [&](const std::string& name, std::vector<InstrumentOptions> instruments, int steps, bool quick,
                 std::vector<std::string> overrides = {}) {
    Case c{"contact", name, dynamic, {}, {}, steps, quick};
    c.overrides.insert(c.overrides.end(), overrides.begin(), overrides.end());
    c.scene = cube;
    c.instruments = std::move(instruments);
    v.push_back(std::move(c));
  };
  // A 2 mm probe pressed 1.5 mm into the top, then in one frame across the top to the far
  // corner, 16 mm away, pressed all the way.
  add("probe jumps 16 mm across the top in one frame",
      {instrument("probe", Type::Probe, 0.002, {{0, V3(2, 2, 17.5)}, {0.005, V3(2, 2, 15.5)}, {0.010, V3(2, 2, 15.5)},
                                       {0.011, V3(13.5, 13.5, 15.5)}})}, 20, true);
  // The same probe in one frame on the far side face, 21 mm away: its straight path runs through
  // the cube and drags the surface through the tissue. Whether a stage converges or stalls
  // changes with the BLAS kernel's rounding; a stall must be rolled back.
  add("probe jumps 21 mm through the cube in one frame",
      {instrument("probe", Type::Probe, 0.002, {{0, V3(2, 2, 17.5)}, {0.005, V3(2, 2, 15.5)}, {0.010, V3(2, 2, 15.5)},
                                       {0.011, V3(15.5, 13, 4)}})}, 20, true);
  v.back().expected = {kConverged, "stalled"};
  add("probe pressed 1.5 mm sweeping at 1 m/s",
      {instrument("probe", Type::Probe, 0.002, {{0, V3(1, 7.5, 17.5)}, {0.005, V3(1, 7.5, 15.5)}, {0.018, V3(14, 7.5, 15.5)}})}, 20,
      false);
  // Pressed 15 mm along the diagonal into the top corner: the corner ends at mid-height.
  const V3 corner(15, 15, 15), diagonal = V3(1, 1, 1).normalized();
  add("probe pressed 15 mm into a corner",
      {instrument("probe", Type::Probe, 0.002, {{0, corner + 2.5 * diagonal}, {0.03, corner + (2 - 15) * diagonal}})}, 35, false);
  add("two probes squeezing 3 mm from opposite faces",
      {instrument("left", Type::Probe, 0.002, {{0, V3(-2, 7.5, 10)}, {0.01, V3(1, 7.5, 10)}}),
       instrument("right", Type::Probe, 0.002, {{0, V3(17, 7.5, 10)}, {0.01, V3(14, 7.5, 10)}})},
      15, true);
  InstrumentOptions grasper = instrument("grasper", Type::Grasper, 0.002, {{0, V3(7.5, 7.5, 15)}, {0.002, V3(7.5, 7.5, 15)},
                                                                 {0.032, V3(7.5, 7.5, 30)}});
  grasper.trajectory[1].closed = true;
  add("grasper lifting the top 15 mm (stretch x2)", {grasper}, 35, false);
  for (const char* mu : {"0", "1"})
    add(std::string("probe sweeping 6 mm, friction ") + mu,
        {instrument("probe", Type::Probe, 0.002, {{0, V3(4.5, 7.5, 17.5)}, {0.005, V3(4.5, 7.5, 15.5)}, {0.035, V3(10.5, 7.5, 15.5)}})},
        35, std::string(mu) == "1", {std::string("contact.friction=") + mu});
  // Triangles of the top face have 1.9 mm legs; a 0.3 mm tip pressed 1 mm inside one.
  add("0.3 mm tip pressed 1 mm inside a triangle",
      {instrument("probe", Type::Probe, 0.0003, {{0, V3(8.1, 7.8, 15.5)}, {0.01, V3(8.1, 7.8, 14.3)}})}, 15, true);
}

// Each instrument type pressing (a grasper lifting) for five frames, the fifth made to fail
// through the stepper's test hook: an exception after its first Newton update, or a negative
// pivot in its factorisation. The step must be rolled back to the bits of the fourth frame's end,
// the instrument's reaction and contacts included.
void failure_cases(std::vector<Case>& v) {
  using Type = InstrumentOptions::Type;
  using Fault = NewtonStepper::InjectedFault;
  using V3 = Eigen::Vector3d;
  const std::vector<std::string> dynamic = {"solver.mode=dynamic", "solver.dt=0.001", "solver.tolerance=1e-6"};
  // The shaft 0.1 mm a frame (at 0.3 mm a frame, 0.7 mm deep with 20 contacts along it, frame 4
  // reached the iteration cap).
  InstrumentOptions shaft = instrument("shaft", Type::Shaft, 0.002, {{0, V3(2.5, 7.5, 17.3)}, {0.03, V3(2.5, 7.5, 14.3)}});
  shaft.length = 0.01;
  shaft.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));  // lying along x
  for (auto& k : shaft.trajectory) k.orientation = shaft.orientation;
  InstrumentOptions grasper = instrument("grasper", Type::Grasper, 0.002, {{0, V3(7.5, 7.5, 15)}, {0.01, V3(7.5, 7.5, 17)}});
  grasper.trajectory[0].closed = true;
  const std::vector<std::pair<std::string, InstrumentOptions>> instruments = {
      {"probe", instrument("probe", Type::Probe, 0.002, {{0, V3(7.5, 7.5, 17.5)}, {0.01, V3(7.5, 7.5, 14.5)}})},
      {"shaft", shaft},
      {"grasper", grasper}};
  for (const auto& [fault, reason, what] : {std::make_tuple(Fault::Exception, kException, "an exception"),
                                           std::make_tuple(Fault::NotPositiveDefinite, "tangent matrix is not positive definite",
                                                           "a negative pivot")}) {
    for (const auto& [name, o] : instruments) {
      Case c{"failure", name + " pressing, " + what + " in frame 5", dynamic, {}, {}, 5, name == "probe"};
      c.scene = tool::package_file(kProbeScene);
      c.instruments = {o};
      c.expected = {reason};
      c.fault = fault;
      c.fault_step = 5;
      v.push_back(std::move(c));
    }
    // The aspiration tube's scene (3 kPa of suction), the tube pressed 0.1 mm further per frame.
    Case c{"failure", std::string("tube sucking, ") + what + " in frame 5", {"solver.mode=dynamic", "solver.dt=0.005"},
           {}, [](LiverModel& m) {
             InstrumentOptions tube = m.instrument(0);
             tube.trajectory.resize(2);
             tube.trajectory[0].position = tube.position;
             tube.trajectory[1].t = 0.05;
             tube.trajectory[1].position = tube.position - Eigen::Vector3d(0, 0, 1e-3);
             m.update_instrument(0, tube);
           },
           5, true};
    c.scene = tool::package_file(kTubeScene);
    c.expected = {reason};
    c.fault = fault;
    c.fault_step = 5;
    v.push_back(std::move(c));
  }
}

std::vector<Case> cases() {
  std::vector<Case> v;
  const std::vector<std::string> stalls = {kStalled};
  const std::vector<std::string> chaotic = {kConverged, kStalled};
  for (double ratio : {1.0, 1e2, 1e4, 1e6}) {
    std::ostringstream n;
    n << "E_c / E_p = " << ratio;
    v.push_back({"capsule stiffness", n.str(), {"capsule.young_modulus=" + std::to_string(3500 * ratio)}, {}, {}, 1, ratio == 1e6});
  }
  for (const char* nu : {"0.3", "0.45", "0.49", "0.499"})
    v.push_back({"Poisson ratio", std::string("nu = ") + nu, {std::string("parenchyma.poisson_ratio=") + nu}, {}, {}, 1,
                 std::string(nu) == "0.499"});
  for (const char* dt : {"1e-5", "1e-3", "0.1", "1"})
    v.push_back({"time step", std::string("dt = ") + dt + " s, 10 steps",
                 {"solver.mode=dynamic", std::string("solver.dt=") + dt, "solver.rayleigh_stiffness=0.02"}, {}, {}, 10,
                 std::string(dt) == "1e-5" || std::string(dt) == "1"});
  for (double f : {0.125, 0.25, 0.5}) {
    std::ostringstream n;
    n << "top " << f * 100 << "% folded through (inverted start)";
    // The half folded through is in the reduced run: its stall ends about twice above its start
    // merit, so a stall detector ten times too lax (mutation NS10) lets it through.
    v.push_back({"inversion", n.str(), {}, {}, fold_above(0.015 * (1 - f)), 1, f == 0.5, f == 0.125 ? chaotic : stalls});
  }
  v.push_back({"inversion", "top 50% folded, dynamic dt = 5 ms, 10 steps", {"solver.mode=dynamic", "solver.dt=0.005"}, {},
               fold_above(0.0075), 10, false});
  for (double a : {0.3, 0.45}) {
    std::ostringstream n;
    n << "interior nodes moved by " << a << " h (slivers)";
    v.push_back({"element quality", n.str(), {}, [a](const Scene& s) { return perturbed_box(s, a, 1e-4); }, {}, 1, a == 0.45});
  }
  v.push_back({"element quality", "moves down to quality 1e-7 (near-degenerate)", {},
               [](const Scene& s) { return perturbed_box(s, 0.49, 1e-7); }, {}, 1, false});
  v.push_back({"100 kPa step", "suction -100 kPa, static", {"loads.0.value=-1e5"}, {}, {}, 1, true, stalls});
  v.push_back({"100 kPa step", "pressure +100 kPa, static", {"loads.0.value=1e5"}, {}, {}, 1, false, stalls});
  v.push_back({"100 kPa step", "suction -100 kPa, dynamic dt = 5 ms, 10 steps",
               {"loads.0.value=-1e5", "solver.mode=dynamic", "solver.dt=0.005"}, {}, {}, 10, true});
  v.push_back({"100 kPa step", "pressure +100 kPa, no line search, static", {"loads.0.value=1e5", "solver.line_search=false"},
               {}, {}, 1, false, chaotic});
  contact_cases(v);
  failure_cases(v);
  return v;
}

}  // namespace

int main(int argc, char** argv) {
  namespace tool = liver_sim::tool;
  bool quick = false;
  std::string scene = tool::package_file("config/scenes/aspiration_cube.yaml"), csv, group;
  std::vector<std::string> extra;  // --set K=V, after each case's own overrides
  const std::vector<Case> all = cases();
  std::vector<std::string> groups;
  std::string group_list;
  for (const Case& c : all)
    if (std::find(groups.begin(), groups.end(), c.group) == groups.end()) {
      groups.push_back(c.group);
      const bool one_word = c.group.find(' ') == std::string::npos;
      group_list += (group_list.empty() ? "" : ", ") + (one_word ? c.group : "'" + c.group + "'");
    }
  CLI::App app(
      "Runs the numerical stress matrix; a Markdown table on standard output; exit status 0 when every\n"
      "case ended as expected, 1 otherwise, 2 on a bad command line.",
      "stress");
  tool::describe(app, "usage: stress [--quick] [--group NAME] [--set K=V]... [--scene FILE] [--csv FILE]\n");
  app.add_flag("--quick", quick, "the reduced matrix of the tests");
  app.add_option("--group", group,
"the cases of one group, one of " + group_list)
      ->option_text("NAME")
      ->check(CLI::IsMember(groups));
  tool::add_overrides(app, extra, "a scene override applied to every case after its own (repeatable)");
  app.add_option("--scene", scene, "replaces the default scene (the aspiration cube)")->option_text("FILE");
  app.add_option("--csv", csv, "also write the rows as CSV")->option_text("FILE");
  if (const std::optional<int> status = tool::parse(app, argc, argv)) return *status;
  std::ofstream csv_out;
  if (!csv.empty()) {
    csv_out.open(csv);
    csv_out << "group,case,expected,result,steps,newton,factorizations,contacts,residual,max_displacement_m,inverted_start,inverted_end,min_quality,ms,detail\n";
  }
  std::cout << "| group | case | expected | result | steps | Newton | factorisations | contacts | residual | max displacement (mm) | inverted start → end | min quality | time (ms) | detail |\n"
            << "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|\n";
  int unexpected = 0;
  for (size_t k = 0; k < all.size(); ++k) {
    Case c = all[k];
    c.overrides.insert(c.overrides.end(), extra.begin(), extra.end());
    if ((quick && !c.quick) || (!group.empty() && c.group != group)) continue;
    std::cerr << "[" << k + 1 << "/" << all.size() << "] " << c.group << ": " << c.name << "\n";
    Outcome o;
    try {
      o = run(c, scene);
    } catch (const std::exception& e) {
      o.result = "FAILED";
      o.detail = std::string("exception: ") + e.what();
    }
    std::string expected = c.expected[0];
    for (size_t e = 1; e < c.expected.size(); ++e) expected += " or " + c.expected[e];
    const bool as_expected =
        o.result != "FAILED" && std::find(c.expected.begin(), c.expected.end(), o.reason) != c.expected.end();
    unexpected += !as_expected;
    const std::string result = (o.result == "detected" ? o.reason : o.result) + (as_expected ? "" : " (UNEXPECTED)");
    std::cout << std::setprecision(3) << "| " << c.group << " | " << c.name << " | " << expected << " | " << result << " | "
              << o.steps << " | " << o.newton << " | " << o.factorizations << " | " << o.contacts << " | " << o.residual << " | " << o.max_u * 1e3 << " | "
              << o.inverted_start << " → " << o.inverted_end << " | " << o.min_quality << " | " << std::setprecision(4)
              << o.ms << " | " << o.detail << " |\n";
    if (csv_out)
      csv_out << c.group << ",\"" << c.name << "\"," << expected << "," << result << "," << o.steps << "," << o.newton << ","
              << o.factorizations << "," << o.contacts << "," << o.residual << "," << o.max_u << "," << o.inverted_start << "," << o.inverted_end << "," << o.min_quality
              << "," << o.ms << ",\"" << o.detail << "\"\n";
  }
  std::cerr << (unexpected ? std::to_string(unexpected) + " case(s) did not end as expected\n" : "every case ended as expected\n");
  return unexpected ? 1 : 0;
}
