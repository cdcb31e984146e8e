// Command-line simulator: runs a scene file and prints one JSON object on standard output.
//   simulate --scene FILE [--set dotted.key=value]... [--threads N] [--vtu FILE] [--csv FILE] [--quiet]
// Progress goes to standard error. Exit status: 0 done, 1 bad input (one line naming the file
// or key), 2 bad command line, 3 a step diverged (the JSON says which).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "liver_sim/io/vtu_writer.h"
#include "liver_sim/simulation/liver_model.h"
#include "tool_io.h"

namespace {

using liver_sim::LiverModel;
using liver_sim::StepResult;
using Json = nlohmann::ordered_json;

struct Options {
  std::string scene, vtu, csv;
  std::vector<std::string> overrides;  // --set, then --threads
  bool quiet = false;
};

// The command line into `o`: the exit status when the tool is to stop, else nothing.
std::optional<int> parse_args(int argc, char** argv, Options* o) {
  namespace tool = liver_sim::tool;
  CLI::App app("", "simulate");
  tool::describe(app,
                 "usage: simulate --scene FILE [--set dotted.key=value]... [--threads N] [--vtu FILE] [--csv FILE] "
                 "[--quiet]\n",
                 "Exit status: 0 done, 1 bad input, 2 bad command line, 3 a step diverged.");
  app.add_option("--scene", o->scene, "YAML scene (see README, 'Scene format')")->option_text("FILE")->required();
  tool::add_overrides(app, o->overrides, "override a scalar of the scene, e.g. --set capsule.enabled=false");
  int threads = 0;
  app.add_option("--threads", threads,
                 "threads of the element loops (solver.threads, default 1, " + tool::thread_bounds() +
                     "; results do not change)")
      ->option_text("N")
      ->check(tool::thread_count());
  app.add_option("--vtu", o->vtu, "write the final mesh with its displacement field (VTK XML)")->option_text("FILE");
  app.add_option("--csv", o->csv, "write the probe displacements after every step")->option_text("FILE");
  app.add_flag("--quiet", o->quiet, "no progress on standard error");
  if (const std::optional<int> status = tool::parse(app, argc, argv)) return status;
  if (threads > 0) o->overrides.push_back("solver.threads=" + std::to_string(threads));
  return std::nullopt;
}

Json json_vec(const Eigen::Vector3d& v) { return Json::array({v[0], v[1], v[2]}); }

const char* status_word(StepResult::Status s) {
  switch (s) {
    case StepResult::Status::Converged: return "converged";
    case StepResult::Status::NotConverged: return "not_converged";
    case StepResult::Status::Diverged: return "diverged";
  }
  return "";
}

int run(const Options& opt) {
  const liver_sim::Scene scene = liver_sim::load_scene(opt.scene, opt.overrides);
  liver_sim::TetMesh mesh = liver_sim::load_scene_mesh(scene);
  std::unique_ptr<LiverModel> model_ptr;
  try {
    model_ptr = std::make_unique<LiverModel>(std::move(mesh), scene);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(opt.scene + ": " + e.what());
  }
  LiverModel& model = *model_ptr;

  std::ofstream csv;
  if (!opt.csv.empty()) {
    csv.open(opt.csv);
    if (!csv) throw std::runtime_error(opt.csv + ": cannot open for writing");
    csv << "step,time";
    for (int p = 0; p < model.num_probes(); ++p)
      for (const char* c : {"_ux", "_uy", "_uz"}) csv << ',' << model.probe_name(p) << c;
    csv << '\n' << std::setprecision(10);
  }

  const bool dynamic = scene.solver.mode == liver_sim::SolverOptions::Mode::Dynamic;
  const int steps = scene.solver.steps;
  std::vector<double> step_ms;
  StepResult last;
  liver_sim::StepTiming sum;
  int iterations = 0, max_iterations = 0, linear_iterations = 0, factorizations = 0, converged_steps = 0,
      steps_done = 0, contact_sweeps = 0, max_contacts = 0;
  auto last_report = std::chrono::steady_clock::now();
  for (int k = 1; k <= steps; ++k) {
    if (!dynamic) model.set_load_scale(static_cast<double>(k) / steps);
    last = model.step();
    ++steps_done;
    step_ms.push_back(last.timing.total_ms);
    sum.assembly_ms += last.timing.assembly_ms;
    sum.factorization_ms += last.timing.factorization_ms;
    sum.solve_ms += last.timing.solve_ms;
    sum.contact_ms += last.timing.contact_ms;
    contact_sweeps += last.contact_sweeps;
    max_contacts = std::max(max_contacts, last.contacts);
    iterations += last.iterations;
    linear_iterations += last.linear_iterations;
    factorizations += last.factorizations;
    max_iterations = std::max(max_iterations, last.iterations);
    converged_steps += last.converged();
    if (csv.is_open()) {
      csv << k << ',' << model.time();
      for (int p = 0; p < model.num_probes(); ++p) {
        const Eigen::Vector3d u = model.probe_displacement(p);
        csv << ',' << u[0] << ',' << u[1] << ',' << u[2];
      }
      csv << '\n';
    }
    const auto now = std::chrono::steady_clock::now();
    if (!opt.quiet && (now - last_report > std::chrono::seconds(1) || k == steps)) {
      std::cerr << "simulate: step " << k << "/" << steps << "  " << status_word(last.status)
                << "  iterations " << last.iterations << "  residual " << last.residual << "\n";
      last_report = now;
    }
    if (last.status == StepResult::Status::Diverged) break;
  }
  if (!opt.vtu.empty()) liver_sim::write_vtu(opt.vtu, model.mesh(), model.displacement());

  std::vector<double> sorted = step_ms;
  std::sort(sorted.begin(), sorted.end());

  Json result;
  result["scene"] = opt.scene;
  result["nodes"] = model.mesh().V.rows();
  result["tetrahedra"] = model.mesh().T.rows();
  result["boundary_triangles"] = model.boundary().rows();
  result["membrane_triangles"] = model.capsule_triangles();
  result["dofs"] = 3 * model.mesh().V.rows();
  result["mode"] = dynamic ? "dynamic" : "static";
  result["converged"] = last.converged();
  result["converged_steps"] = converged_steps;
  result["status"] = status_word(last.status);
  result["message"] = last.message;
  result["residual"] = last.residual;
  result["steps"] = steps_done;
  result["time"] = model.time();
  result["newton_iterations"] = {{"total", iterations}, {"max_per_step", max_iterations}};
  result["gmres_iterations"] = linear_iterations;
  result["factorizations"] = factorizations;
  result["step_time_ms"] = {{"min", sorted.front()}, {"median", sorted[sorted.size() / 2]}, {"max", sorted.back()}};
  result["phase_time_ms_per_step"] = {{"assembly", sum.assembly_ms / steps_done},
                                      {"factorization", sum.factorization_ms / steps_done},
                                      {"solve", sum.solve_ms / steps_done},
                                      {"contact", sum.contact_ms / steps_done}};
  result["contact"] = {{"max_contacts", max_contacts},
                       {"gauss_seidel_sweeps", contact_sweeps},
                       {"problems_solved", model.contact().solves()},
                       {"compliance_columns", model.contact().compliance_columns()}};
  result["max_displacement"] = model.max_displacement();
  Json& probes = result["probes"] = Json::object();
  for (int p = 0; p < model.num_probes(); ++p)
    probes[model.probe_name(p)] = {{"displacement", json_vec(model.probe_displacement(p))}};
  Json& instruments = result["instruments"] = Json::object();
  for (int i = 0; i < model.num_instruments(); ++i) {
    const liver_sim::InstrumentReaction& r = model.instrument_reaction(i);
    instruments[model.instrument(i).name] = {
        {"force", json_vec(r.force)}, {"torque", json_vec(r.torque)}, {"contacts", r.contacts}};
  }
  liver_sim::tool::print_json(std::cout, result);
  return last.status == StepResult::Status::Diverged ? 3 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  if (const std::optional<int> status = parse_args(argc, argv, &opt)) return *status;
  try {
    return run(opt);
  } catch (const std::exception& e) {
    std::cerr << "simulate: " << e.what() << "\n";
    return 1;
  }
}
