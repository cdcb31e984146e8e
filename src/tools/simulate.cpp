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
#include <sstream>
#include <string>
#include <vector>

#include "liver_sim/simulation/liver_model.h"
#include "json_text.h"
#include "liver_sim/io/vtu_writer.h"

namespace {

using liver_sim::json_string;

using liver_sim::LiverModel;
using liver_sim::StepResult;

const char* kUsage =
    "usage: simulate --scene FILE [--set dotted.key=value]... [--threads N] [--vtu FILE] [--csv FILE] [--quiet]\n"
    "  --scene FILE   YAML scene (see README, 'Scene format')\n"
    "  --set K=V      override a scalar of the scene, e.g. --set capsule.enabled=false\n"
    "  --threads N    threads of the element loops (solver.threads, default 1; results do not change)\n"
    "  --vtu FILE     write the final mesh with its displacement field (VTK XML)\n"
    "  --csv FILE     write the probe displacements after every step\n"
    "  --quiet        no progress on standard error\n"
    "  --help         this text\n"
    "Exit status: 0 done, 1 bad input, 2 bad command line, 3 a step diverged.\n";

struct Options {
  std::string scene, vtu, csv;
  std::vector<std::string> overrides;
  bool quiet = false;
};

bool parse_args(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](std::string* out) {
      if (i + 1 >= argc) return false;
      *out = argv[++i];
      return true;
    };
    std::string v;
    if (a == "--scene" && value(&o->scene)) continue;
    if (a == "--vtu" && value(&o->vtu)) continue;
    if (a == "--csv" && value(&o->csv)) continue;
    if (a == "--set" && value(&v)) {
      o->overrides.push_back(v);
      continue;
    }
    if (a == "--threads" && value(&v)) {
      o->overrides.push_back("solver.threads=" + v);
      continue;
    }
    if (a == "--quiet") {
      o->quiet = true;
      continue;
    }
    return false;
  }
  return !o->scene.empty();
}

std::string json_vec(const Eigen::Vector3d& v) {
  std::ostringstream s;
  s << std::setprecision(9) << '[' << v[0] << ", " << v[1] << ", " << v[2] << ']';
  return s.str();
}

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

  std::ostringstream js;
  js << std::setprecision(9) << "{\n"
     << "  \"scene\": " << json_string(opt.scene) << ",\n"
     << "  \"nodes\": " << model.mesh().V.rows() << ",\n"
     << "  \"tetrahedra\": " << model.mesh().T.rows() << ",\n"
     << "  \"boundary_triangles\": " << model.boundary().rows() << ",\n"
     << "  \"membrane_triangles\": " << model.capsule_triangles() << ",\n"
     << "  \"dofs\": " << 3 * model.mesh().V.rows() << ",\n"
     << "  \"mode\": \"" << (dynamic ? "dynamic" : "static") << "\",\n"
     << "  \"converged\": " << (last.converged() ? "true" : "false") << ",\n"
     << "  \"converged_steps\": " << converged_steps << ",\n"
     << "  \"status\": \"" << status_word(last.status) << "\",\n"
     << "  \"message\": " << json_string(last.message) << ",\n"
     << "  \"residual\": " << last.residual << ",\n"
     << "  \"steps\": " << steps_done << ",\n"
     << "  \"time\": " << model.time() << ",\n"
     << "  \"newton_iterations\": {\"total\": " << iterations << ", \"max_per_step\": " << max_iterations << "},\n"
     << "  \"gmres_iterations\": " << linear_iterations << ",\n"
     << "  \"factorizations\": " << factorizations << ",\n"
     << "  \"step_time_ms\": {\"min\": " << sorted.front() << ", \"median\": " << sorted[sorted.size() / 2]
     << ", \"max\": " << sorted.back() << "},\n"
     << "  \"phase_time_ms_per_step\": {\"assembly\": " << sum.assembly_ms / steps_done
     << ", \"factorization\": " << sum.factorization_ms / steps_done
     << ", \"solve\": " << sum.solve_ms / steps_done << ", \"contact\": " << sum.contact_ms / steps_done << "},\n"
     << "  \"contact\": {\"max_contacts\": " << max_contacts << ", \"gauss_seidel_sweeps\": " << contact_sweeps
     << ", \"problems_solved\": " << model.contact().solves() << ", \"compliance_columns\": " << model.contact().compliance_columns()
     << "},\n"
     << "  \"max_displacement\": " << model.max_displacement() << ",\n"
     << "  \"probes\": {";
  for (int p = 0; p < model.num_probes(); ++p)
    js << (p ? ", " : "") << "\n    " << json_string(model.probe_name(p)) << ": {\"displacement\": "
       << json_vec(model.probe_displacement(p)) << "}";
  js << (model.num_probes() ? "\n  " : "") << "},\n  \"instruments\": {";
  for (int i = 0; i < model.num_instruments(); ++i) {
    const liver_sim::InstrumentReaction& r = model.instrument_reaction(i);
    js << (i ? ", " : "") << "\n    " << json_string(model.instrument(i).name) << ": {\"force\": " << json_vec(r.force)
       << ", \"torque\": " << json_vec(r.torque) << ", \"contacts\": " << r.contacts << "}";
  }
  js << (model.num_instruments() ? "\n  " : "") << "}\n}\n";
  std::cout << js.str();
  return last.status == StepResult::Status::Diverged ? 3 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]) == "--help" || std::string(argv[i]) == "-h") {
      std::cout << kUsage;
      return 0;
    }
  Options opt;
  if (!parse_args(argc, argv, &opt)) {
    std::cerr << kUsage;
    return 2;
  }
  try {
    return run(opt);
  } catch (const std::exception& e) {
    std::cerr << "simulate: " << e.what() << "\n";
    return 1;
  }
}
