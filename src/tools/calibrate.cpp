// Material calibration from measured probe displacements, as for the published composite model:
// first the parenchyma Young's modulus on the model without capsule, then the capsule Young's
// modulus at a fixed capsule thickness with the parenchyma modulus held at its fitted value.
//   calibrate --scene FILE --synthesize OUT.csv [--set dotted.key=value]... [--levels 0.5,1]
//   calibrate --scene FILE --measured IN.csv [--set dotted.key=value]...
//             [--start-parenchyma E0] [--start-capsule E0]
//             [--expect-parenchyma E] [--expect-capsule E] [--tolerance REL]
// --synthesize writes the probe displacements of the scene (with its moduli) without and with
// capsule at each load level, as the measurement CSV that --measured reads:
//   stage,load_scale,probe,ux,uy,uz     stage: parenchyma (no capsule) | capsule; u in m
// A load level s runs the scene's static increments up to s times its loads, from the rest shape.
// Each modulus is found by a 1-D search in ln E (bracketed by expanding steps from the start,
// then Brent's method, Boost.Math's, to about 1e-5 in ln E: 2^-20 relative in ln(E / 1 Pa))
// minimising the mean squared displacement misfit; a solve that does not converge, or a modulus
// outside the model's bounds, counts as a misfit above any other (a failed solve). Start values
// default to the scene's moduli.
// Progress (one line per model evaluation) goes to standard error, one JSON object to standard
// output. Exit status: 0 fitted, 1 bad input (one line naming the file or key), 2 bad command
// line, 3 the fit failed (a stage with no converged evaluation, no minimum within a factor 1e6
// of its start or its minimum next to a failed solve, or a fitted modulus further than
// --tolerance, relative, from its --expect-* value) or, with --synthesize, a solve failed.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iostream>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <boost/math/tools/minima.hpp>

#include "liver_sim/simulation/liver_model.h"
#include "tool_io.h"

namespace {

using liver_sim::LiverModel;
using liver_sim::Scene;
using liver_sim::StepResult;
using liver_sim::TetMesh;

const char* kHeader = "stage,load_scale,probe,ux,uy,uz";

// The two calibration stages, in the order they are fitted.
enum Stage { kParenchyma = 0, kCapsule = 1 };
const char* const kStageNames[] = {"parenchyma", "capsule"};

struct Options {
  std::string scene, synthesize, measured;
  std::vector<std::string> overrides;
  std::vector<double> levels{1.0};
  double start[2] = {0, 0}, expect[2] = {0, 0};  // Pa, when given
  bool has_start[2] = {false, false}, has_expect[2] = {false, false};
  double tolerance = 0.01;
};

bool parse_number(const std::string& text, double* out) {
  const char* begin = text.c_str();
  char* end = nullptr;
  *out = std::strtod(begin, &end);
  return end != begin && *end == '\0' && std::isfinite(*out);
}

// The command line into `o`: the exit status when the tool is to stop, else nothing.
std::optional<int> parse_args(int argc, char** argv, Options* o) {
  namespace tool = liver_sim::tool;
  CLI::App app("", "calibrate");
  tool::describe(app,
                 "usage: calibrate --scene FILE --synthesize OUT.csv [--set K=V]... [--levels 0.5,1]\n"
                 "       calibrate --scene FILE --measured IN.csv [--set K=V]... [--start-parenchyma E0]\n"
                 "                 [--start-capsule E0] [--expect-parenchyma E] [--expect-capsule E] [--tolerance REL]\n",
                 "Exit status: 0 fitted, 1 bad input, 2 bad command line, 3 the fit failed or a fitted modulus is\n"
                 "off its expected one by more than the tolerance (--synthesize: a solve failed).");
  app.add_option("--scene", o->scene, "YAML scene (see README, 'Scene format'); a static scene with probes")
      ->option_text("FILE")
      ->required();
  tool::add_overrides(app, o->overrides, "override a scalar of the scene, e.g. --set capsule.thickness=93e-6");
  app.add_option("--synthesize", o->synthesize, "write the scene's probe displacements without and with capsule")
      ->option_text("OUT.csv");
  CLI::Option* levels =
      tool::add_list(app, "--levels", "L,...", o->levels,
                     "load levels to synthesize, fractions of the scene's loads, > 0 (default 1)")
          ->check(tool::positive());
  app.add_option("--measured", o->measured, "fit the parenchyma, then the capsule Young's modulus to these data")
      ->option_text("IN.csv");
  CLI::Option* start[2] = {
      app.add_option("--start-parenchyma", o->start[kParenchyma], "search start (Pa, > 0; default: the scene's)"),
      app.add_option("--start-capsule", o->start[kCapsule], "search start (Pa, > 0; default: the scene's)")};
  CLI::Option* expect[2] = {
      app.add_option("--expect-parenchyma", o->expect[kParenchyma],
                     "known modulus (Pa, > 0): exit 3 when the fit is off by more than --tolerance"),
      app.add_option("--expect-capsule", o->expect[kCapsule],
                     "known modulus (Pa, > 0): exit 3 when the fit is off by more than --tolerance")};
  for (CLI::Option* option : start) option->option_text("E0")->check(tool::positive());
  for (CLI::Option* option : expect) option->option_text("E")->check(tool::positive());
  app.add_option("--tolerance", o->tolerance,
                 "how far, relative, a fitted modulus may be from its expected one, > 0\n(default 0.01)")
      ->option_text("REL")
      ->check(tool::positive());
  app.callback([&] {
    if (o->synthesize.empty() == o->measured.empty())
      throw CLI::ValidationError("give exactly one of --synthesize and --measured");
    for (int stage : {kParenchyma, kCapsule}) {
      o->has_start[stage] = start[stage]->count() > 0;
      o->has_expect[stage] = expect[stage]->count() > 0;
    }
    if (!o->synthesize.empty()) {
      if (o->has_start[0] || o->has_start[1] || o->has_expect[0] || o->has_expect[1])
        throw CLI::ValidationError("--start-* and --expect-* apply to --measured");
      // The fit reads one row per stage, level and probe.
      for (auto l = o->levels.begin(); l != o->levels.end(); ++l)
        if (std::find(o->levels.begin(), l, *l) != l) throw CLI::ValidationError("--levels", "repeats a level");
    } else if (levels->count()) {
      throw CLI::ValidationError("--levels applies to --synthesize (the measurements carry their load levels)");
    }
  });
  return tool::parse(app, argc, argv);
}

// The scene of one stage: without capsule (stage 1) or with it (stage 2), at the given moduli.
Scene stage_scene(const Scene& base, Stage stage, double parenchyma_modulus, double capsule_modulus) {
  Scene s = base;
  s.parenchyma.young_modulus = parenchyma_modulus;
  s.capsule.enabled = stage == kCapsule;
  s.capsule.young_modulus = capsule_modulus;
  return s;
}

// Probe displacements (m) by probe name, one map per load level.
using Displacements = std::vector<std::map<std::string, Eigen::Vector3d>>;

// Static solve at each load level from the rest shape: the scene's increments up to the level
// times its loads. Returns "" when every increment converged, else why one did not.
std::string solve_levels(const TetMesh& mesh, const Scene& scene, const std::vector<double>& levels,
                         Displacements* u) {
  LiverModel model(mesh, scene);
  const int steps = scene.solver.steps;
  u->assign(levels.size(), {});
  for (size_t l = 0; l < levels.size(); ++l) {
    model.reset();
    for (int k = 1; k <= steps; ++k) {
      model.set_load_scale(levels[l] * k / steps);
      const StepResult r = model.step();
      if (!r.converged()) {
        std::ostringstream why;
        why << "load level " << levels[l] << ", increment " << k << "/" << steps << ": "
            << (r.status == StepResult::Status::Diverged ? "diverged" : "not converged")
            << (r.message.empty() ? "" : " (" + r.message + ")");
        return why.str();
      }
    }
    for (int p = 0; p < model.num_probes(); ++p) (*u)[l][model.probe_name(p)] = model.probe_displacement(p);
  }
  return "";
}

struct Reading {
  int level;  // index into the stage's load levels
  std::string probe;
  Eigen::Vector3d u;  // m
};

struct StageData {
  std::vector<double> levels;  // ascending
  std::vector<Reading> readings;
  double mean_square_measured = 0;  // m^2, per reading
};

std::string trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r");
  return a == std::string::npos ? "" : s.substr(a, s.find_last_not_of(" \t\r") - a + 1);
}

// Reads and checks a measurement CSV; throws std::runtime_error naming the file and line.
std::vector<StageData> read_measurements(const std::string& path, const Scene& scene) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  std::string probes;
  for (const liver_sim::ProbeOptions& p : scene.probes) probes += (probes.empty() ? "" : ", ") + p.name;
  struct Row {
    double load_scale;
    std::string probe;
    Eigen::Vector3d u;
  };
  std::vector<Row> rows[2];
  std::string line;
  int number = 0;
  bool header = false;
  while (std::getline(in, line)) {
    ++number;
    line = trim(line);
    if (line.empty()) continue;
    const std::string where = path + ":" + std::to_string(number) + ": ";
    if (!header) {
      if (line != kHeader) throw std::runtime_error(where + "expected the header '" + kHeader + "'");
      header = true;
      continue;
    }
    std::vector<std::string> f;
    std::stringstream fields(line);
    for (std::string item; std::getline(fields, item, ',');) f.push_back(trim(item));
    if (line.back() == ',') f.push_back("");
    if (f.size() != 6)
      throw std::runtime_error(where + "expected 6 comma-separated fields, found " + std::to_string(f.size()));
    const auto stage = std::find(std::begin(kStageNames), std::end(kStageNames), f[0]);
    if (stage == std::end(kStageNames))
      throw std::runtime_error(where + "stage must be 'parenchyma' or 'capsule', not '" + f[0] + "'");
    Row row;
    if (!parse_number(f[1], &row.load_scale) || row.load_scale <= 0)
      throw std::runtime_error(where + "load_scale '" + f[1] + "' is not a positive number");
    if (std::none_of(scene.probes.begin(), scene.probes.end(), [&](const auto& p) { return p.name == f[2]; }))
      throw std::runtime_error(where + "probe '" + f[2] + "' is not in the scene (its probes: " +
                               (probes.empty() ? "none" : probes) + ")");
    row.probe = f[2];
    for (int c = 0; c < 3; ++c)
      if (!parse_number(f[3 + c], &row.u[c]))
        throw std::runtime_error(where + "u" + "xyz"[c] + " '" + f[3 + c] + "' is not a finite number");
    std::vector<Row>& stage_rows = rows[stage - std::begin(kStageNames)];
    for (const Row& r : stage_rows)
      if (r.load_scale == row.load_scale && r.probe == row.probe)
        throw std::runtime_error(where + "a second row for stage " + f[0] + ", load_scale " + f[1] + ", probe " +
                                 f[2]);
    stage_rows.push_back(row);
  }
  if (!header) throw std::runtime_error(path + ": empty (expected the header '" + kHeader + "')");

  std::vector<StageData> data(2);
  for (int s : {kParenchyma, kCapsule}) {
    if (rows[s].empty()) throw std::runtime_error(path + ": no rows for stage '" + kStageNames[s] + "'");
    StageData& d = data[s];
    for (const Row& r : rows[s]) d.levels.push_back(r.load_scale);
    std::sort(d.levels.begin(), d.levels.end());
    d.levels.erase(std::unique(d.levels.begin(), d.levels.end()), d.levels.end());
    for (const Row& r : rows[s]) {
      const int level = std::lower_bound(d.levels.begin(), d.levels.end(), r.load_scale) - d.levels.begin();
      d.readings.push_back({level, r.probe, r.u});
      d.mean_square_measured += r.u.squaredNorm() / rows[s].size();
    }
    // Nothing to fit: the relative misfit and the modulus would both be undefined.
    if (d.mean_square_measured == 0)
      throw std::runtime_error(path + ": every displacement of stage '" + kStageNames[s] + "' is zero");
  }
  return data;
}

// Mean over the readings of |u_model - u_measured|^2 (m^2).
double mean_square_misfit(const StageData& data, const Displacements& u) {
  double sum = 0;
  for (const Reading& r : data.readings) sum += (u[r.level].at(r.probe) - r.u).squaredNorm();
  return sum / data.readings.size();
}

// Search in x = ln E: the first step, the growth of the bracketing steps and how far from the
// start the bracket may reach; Brent's method stops within 2^(1 - kBits) |x| + 2^(-1 - kBits) of
// the minimum (about 1e-5 in ln E, relative in E, for moduli of kPa to MPa), after at most
// kMaxIterations steps.
constexpr double kFirstStep = 0.6931471805599453;  // ln 2
constexpr double kGrowth = 1.618033988749895;      // golden ratio
constexpr double kReach = 13.815510557964274;      // ln 1e6
constexpr int kBits = 21;
constexpr std::uintmax_t kMaxIterations = 100;
// Boost's parabolic steps need finite values: a failed solve's misfit (infinite) enters them as
// this, above any misfit (m^2) and small enough that their products of it stay finite.
constexpr double kFailedMisfit = 1e300;

struct Minimum {
  double x = 0;
  double f = std::numeric_limits<double>::infinity();
  std::string failure;  // "" when a minimum was bracketed and refined
};

// Minimises f over x within kReach of x0: walks downhill with growing steps until f rises on
// both sides, then refines the bracket with Brent's method (Boost.Math). A start whose solve
// fails is first replaced by the nearest converged point on either side. Each x is solved once.
// A minimum next to a failed solve (the nearest point tried on either side; Brent's final
// bracket ends on them) lies on the edge of convergence, not at a fit, and is reported as a
// failure.
Minimum minimize(double x0, const std::function<double(double)>& misfit) {
  std::map<double, double> tried;  // x -> f(x)
  auto f = [&](double x) {
    const auto [at, fresh] = tried.try_emplace(x, 0.0);
    if (fresh) at->second = misfit(x);
    return at->second;
  };
  double a = x0, fa = f(a);
  for (double step = kFirstStep; !std::isfinite(fa) && step <= kReach; step *= kGrowth)
    for (double side : {step, -step})
      if (!std::isfinite(fa)) fa = f(a = x0 + side);
  if (!std::isfinite(fa)) return {x0, fa, "no converged solve within a factor 1e6 of the start"};
  double b = a + kFirstStep, fb = f(b);
  if (fb > fa) std::swap(a, b), std::swap(fa, fb);
  double c;
  for (;;) {
    c = std::clamp(b + kGrowth * (b - a), x0 - kReach, x0 + kReach);
    if (c == b) return {b, fb, "the misfit still falls a factor 1e6 from the start"};
    if (f(c) > fb) break;
    a = b, b = c, fb = f(c);
  }
  std::uintmax_t iterations = kMaxIterations;
  const double x = boost::math::tools::brent_find_minima(
                       [&](double x) {
                         const double fx = f(x);
                         return std::isfinite(fx) ? fx : kFailedMisfit;
                       },
                       std::min(a, c), std::max(a, c), kBits, iterations)
                       .first;
  if (iterations >= kMaxIterations) return {x, f(x), "Brent's method did not converge"};
  const auto at = tried.find(x), right = std::next(at);
  const bool bordered = (at != tried.begin() && !std::isfinite(std::prev(at)->second)) ||
                        (right != tried.end() && !std::isfinite(right->second));
  return {x, f(x), bordered ? "the minimum borders on a failed solve" : ""};
}

struct StageFit {
  double start = 0;          // Pa
  double young_modulus = 0;  // Pa
  double mean_square = std::numeric_limits<double>::infinity();  // m^2
  int evaluations = 0, failed = 0;
  std::string failure;
};

StageFit fit_stage(const TetMesh& mesh, const Scene& base, Stage stage, const StageData& data, double start,
                   double parenchyma_modulus) {
  StageFit fit;
  fit.start = start;
  auto misfit = [&](double x) {
    const double modulus = std::exp(x);
    const Scene scene = stage == kParenchyma ? stage_scene(base, stage, modulus, base.capsule.young_modulus)
                                             : stage_scene(base, stage, parenchyma_modulus, modulus);
    Displacements u;
    std::string why;
    try {
      why = solve_levels(mesh, scene, data.levels, &u);
    } catch (const std::invalid_argument& e) {  // a modulus the model refuses (out of its bounds)
      why = e.what();
    }
    ++fit.evaluations;
    std::cerr << "calibrate: " << std::setw(10) << std::left << kStageNames[stage] << std::right << " E "
              << std::setprecision(9) << std::setw(15) << modulus << " Pa  ";
    if (!why.empty()) {
      ++fit.failed;
      std::cerr << "failed: " << why << "\n";
      return std::numeric_limits<double>::infinity();
    }
    const double m = mean_square_misfit(data, u);
    std::cerr << "rms misfit " << std::setprecision(6) << std::sqrt(m) << " m\n";
    return m;
  };
  const Minimum best = minimize(std::log(start), misfit);
  fit.young_modulus = std::exp(best.x);
  fit.mean_square = best.f;
  fit.failure = best.failure;
  return fit;
}

int synthesize(const Options& opt, const Scene& base, const TetMesh& mesh) {
  std::ofstream out(opt.synthesize);
  if (!out) throw std::runtime_error(opt.synthesize + ": cannot open for writing");
  out << kHeader << '\n' << std::setprecision(17);
  int rows = 0;
  for (Stage stage : {kParenchyma, kCapsule}) {
    Displacements u;
    const std::string why = solve_levels(
        mesh, stage_scene(base, stage, base.parenchyma.young_modulus, base.capsule.young_modulus), opt.levels, &u);
    if (!why.empty()) {
      std::cerr << "calibrate: the " << kStageNames[stage] << " stage did not solve: " << why << "\n";
      return 3;
    }
    for (size_t l = 0; l < opt.levels.size(); ++l)
      for (const liver_sim::ProbeOptions& p : base.probes) {
        const Eigen::Vector3d& d = u[l].at(p.name);
        out << kStageNames[stage] << ',' << opt.levels[l] << ',' << p.name << ',' << d[0] << ',' << d[1] << ','
            << d[2] << '\n';
        ++rows;
      }
  }
  out.close();
  if (!out) throw std::runtime_error(opt.synthesize + ": write failed");
  std::cerr << "calibrate: wrote " << rows << " rows to " << opt.synthesize << "\n";
  return 0;
}

int calibrate(const Options& opt, const Scene& base, const TetMesh& mesh) {
  const std::vector<StageData> data = read_measurements(opt.measured, base);
  const double defaults[2] = {base.parenchyma.young_modulus, base.capsule.young_modulus};
  std::optional<StageFit> fits[2];
  bool ok = true;
  for (Stage stage : {kParenchyma, kCapsule}) {
    const double parenchyma_modulus = fits[kParenchyma] ? fits[kParenchyma]->young_modulus : 0;
    fits[stage] = fit_stage(mesh, base, stage, data[stage],
                            opt.has_start[stage] ? opt.start[stage] : defaults[stage], parenchyma_modulus);
    if (!fits[stage]->failure.empty()) {
      ok = false;
      break;  // the capsule stage needs the parenchyma modulus
    }
  }

  nlohmann::ordered_json result;
  result["scene"] = opt.scene;
  result["measured"] = opt.measured;
  result["capsule_thickness"] = base.capsule.thickness;
  int evaluations = 0;
  for (Stage stage : {kParenchyma, kCapsule}) {
    nlohmann::ordered_json& js = result[kStageNames[stage]];
    if (!fits[stage]) continue;  // null
    const StageFit& f = *fits[stage];
    const StageData& d = data[stage];
    const double rms = std::sqrt(f.mean_square);
    evaluations += f.evaluations;
    js["young_modulus"] = f.failure.empty() ? f.young_modulus : std::numeric_limits<double>::quiet_NaN();
    js["start"] = f.start;
    js["rms_misfit"] = rms;
    js["relative_misfit"] = rms / std::sqrt(d.mean_square_measured);
    js["readings"] = d.readings.size();
    js["load_levels"] = d.levels.size();
    js["evaluations"] = f.evaluations;
    js["failed_evaluations"] = f.failed;
    if (!f.failure.empty()) js["failure"] = f.failure;
    if (opt.has_expect[stage] && f.failure.empty()) {
      const double error = (f.young_modulus - opt.expect[stage]) / opt.expect[stage];
      ok = ok && std::abs(error) <= opt.tolerance;
      js["expected"] = opt.expect[stage];
      js["relative_error"] = error;
    }
  }
  result["evaluations"] = evaluations;
  result["tolerance"] = opt.tolerance;
  result["ok"] = ok;
  liver_sim::tool::print_json(std::cout, result);
  return ok ? 0 : 3;
}

int run(const Options& opt) {
  const Scene scene = liver_sim::load_scene(opt.scene, opt.overrides);
  if (scene.solver.mode != liver_sim::SolverOptions::Mode::Static)
    throw std::runtime_error(opt.scene + ": solver.mode must be static for a calibration");
  if (scene.probes.empty()) throw std::runtime_error(opt.scene + ": probes: the scene has none to compare");
  const TetMesh mesh = liver_sim::load_scene_mesh(scene);
  try {
    return opt.synthesize.empty() ? calibrate(opt, scene, mesh) : synthesize(opt, scene, mesh);
  } catch (const std::invalid_argument& e) {  // from the model: a scene it cannot build
    throw std::runtime_error(opt.scene + ": " + e.what());
  }
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  if (const std::optional<int> status = parse_args(argc, argv, &opt)) return *status;
  try {
    return run(opt);
  } catch (const std::exception& e) {
    std::cerr << "calibrate: " << e.what() << "\n";
    return 1;
  }
}
