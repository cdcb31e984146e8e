// Registration benchmark without hardware (doc/registration.md). Ground truth: the scene's
// static equilibrium (the pre-operative model), then the same model lifted by a known force on
// the underside of the right lobe, ramped over the frames (a retractor lifting the liver). Each
// frame a camera renders a partial, noisy cloud of the ground truth's visible surface
// (render_surface_cloud), with outliers, and the model registers to it, warm-started from the
// previous frame. Reported: the target registration error (TRE) of the tumour probes and vessel
// bifurcations against the ground truth before and after registration, the surface error, and
// the time per frame.
//   register_bench --scene FILE [--set K=V]... [--frames N] [--lift NEWTONS] [--repeats R]
//                  [--noise M,...] [--visible FRACTION,...] [--outliers FRACTION,...]
//                  [--csv FILE] [--quiet]
// Every combination of the lists is one CSV row (standard output or --csv), over R runs with
// other random clouds: TRE and surface errors averaged, maxima the largest, frame times pooled.
// Progress on stderr.
// Pin it (taskset -c 0) for timings.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "liver_sim/liver_model.h"
#include "liver_sim/registration.h"
#include "scenarios.h"

namespace {

using namespace liver_sim;

const char* kUsage =
    "usage: register_bench --scene FILE [--set K=V]... [--frames N] [--lift NEWTONS] [--repeats R]\n"
    "                      [--noise M,...] [--visible FRACTION,...] [--outliers FRACTION,...]\n"
    "                      [--csv FILE] [--quiet]\n";

std::vector<double> list(const std::string& s) {
  std::vector<double> v;
  std::stringstream in(s);
  std::string part;
  while (std::getline(in, part, ',')) v.push_back(std::stod(part));
  if (v.empty()) throw std::invalid_argument("empty list");
  return v;
}

struct Options {
  std::string scene, csv;
  std::vector<std::string> overrides;
  int frames = 10;
  double lift = 5.0;  // N
  int repeats = 1;    // runs of each case with other random draws
  std::vector<double> noise{1e-3}, visible{0.3}, outliers{0.0};
  bool quiet = false;
};

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    if (a == "--scene") o.scene = value();
    else if (a == "--set") o.overrides.push_back(value());
    else if (a == "--frames") o.frames = std::stoi(value());
    else if (a == "--lift") o.lift = std::stod(value());
    else if (a == "--repeats") o.repeats = std::stoi(value());
    else if (a == "--noise") o.noise = list(value());
    else if (a == "--visible") o.visible = list(value());
    else if (a == "--outliers") o.outliers = list(value());
    else if (a == "--csv") o.csv = value();
    else if (a == "--quiet") o.quiet = true;
    else throw std::invalid_argument("unknown argument " + a);
  }
  if (o.scene.empty()) throw std::invalid_argument("--scene is required");
  if (o.frames < 1 || o.repeats < 1) throw std::invalid_argument("--frames and --repeats must be >= 1");
  return o;
}

std::vector<Eigen::Vector3d> target_positions(const LiverModel& m) {
  std::vector<Eigen::Vector3d> p;
  for (const TrackedTarget& t : tracked_targets(m)) p.push_back(t.position);
  return p;
}

struct Errors {
  double mean = 0, max = 0;
  int worst = 0;  // index of the target with the largest error
};
Errors distance(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b) {
  Errors e;
  for (size_t i = 0; i < a.size(); ++i) {
    const double d = (a[i] - b[i]).norm();
    e.mean += d / a.size();
    if (d > e.max) e.max = d, e.worst = static_cast<int>(i);
  }
  return e;
}

double boundary_error(const LiverModel& m, const Eigen::VectorXd& truth) {
  // RMS over the boundary nodes (the surface error), m.
  std::vector<char> on(m.mesh().V.rows(), 0);
  for (int t = 0; t < m.boundary().rows(); ++t)
    for (int j = 0; j < 3; ++j) on[m.boundary()(t, j)] = 1;
  double sum = 0;
  int n = 0;
  for (size_t i = 0; i < on.size(); ++i)
    if (on[i]) {
      sum += (m.positions().segment<3>(3 * i) - truth.segment<3>(3 * i)).squaredNorm();
      ++n;
    }
  return std::sqrt(sum / n);
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  try {
    opt = parse(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "register_bench: " << e.what() << "\n" << kUsage;
    return 2;
  }
  try {
    Scene scene = load_scene(opt.scene, opt.overrides);
    const TetMesh mesh = load_scene_mesh(scene);
    // Ground truth frames: a model per lift value, each solved tightly from rest.
    std::vector<Eigen::VectorXd> truth;
    std::vector<std::vector<Eigen::Vector3d>> truth_targets;
    Scene truth_scene = scene;
    truth_scene.solver.mode = SolverOptions::Mode::Static;
    truth_scene.solver.tolerance = 1e-10;
    truth_scene.solver.max_iterations = 100;
    truth_scene.loads.push_back(underside_lift(mesh, 0.0));
    for (int k = 0; k <= opt.frames; ++k) {
      truth_scene.loads.back() = underside_lift(mesh, opt.lift * k / opt.frames);
      LiverModel m(mesh, truth_scene);
      const StepResult r = m.step();
      if (!r.converged()) throw std::runtime_error("ground truth frame " + std::to_string(k) + " did not converge: " + r.message);
      truth.push_back(m.positions());
      truth_targets.push_back(target_positions(m));
      if (!opt.quiet) std::cerr << "\rground truth " << k << "/" << opt.frames << std::flush;
    }
    if (!opt.quiet) std::cerr << "\n";

    // The pre-operative model: the scene at its equilibrium (frame 0 of the truth, no lift).
    LiverModel model(mesh, scene);
    const Eigen::VectorXd& preoperative = truth[0];
    const std::vector<Eigen::Vector3d>& preoperative_targets = truth_targets[0];
    std::vector<std::string> names;
    for (const TrackedTarget& t : tracked_targets(model)) names.push_back(t.name);

    std::ofstream file;
    if (!opt.csv.empty()) file.open(opt.csv);
    std::ostream& out = opt.csv.empty() ? std::cout : file;
    out << "noise_m,visible_request,visible_fraction,outlier_fraction,frames,cloud_points,used_points,"
           "correspondences,tre_unregistered_mean_mm,tre_unregistered_max_mm,tre_mean_mm,tre_max_mm,"
           "tre_worst_frame_max_mm,surface_error_mm,spring_rms_mm,frame_median_ms,frame_max_ms,filter_ms,"
           "correspondence_ms,solve_ms,newton_per_frame,factorizations_per_frame,diverged,tumour_tre_mean_mm,"
           "worst_target\n";
    out << std::setprecision(6);
    const int cases = static_cast<int>(opt.noise.size() * opt.visible.size() * opt.outliers.size());
    int done = 0;
    for (double noise : opt.noise)
      for (double visible : opt.visible)
        for (double outliers : opt.outliers) {
          CameraView view = front_view(preoperative);
          view.visible_fraction = visible;
          view.noise = noise;
          view.outlier_fraction = outliers;
          std::vector<double> frame_ms;
          double worst = 0, achieved = 0, tre_mean = 0, tre_max = 0, surface_error = 0, rms = 0, tumour = 0;
          std::string worst_target;
          int newton = 0, diverged = 0, cloud_points = 0, factorizations = 0;
          double filter_ms = 0, correspondence_ms = 0, solve_ms = 0;
          const int runs = opt.frames * opt.repeats;
          RegistrationFrame last;
          for (int r = 0; r < opt.repeats; ++r) {
            model.reset();
            model.set_positions(preoperative);
            SurfaceRegistration registration(model, scene.registration);
            for (int k = 1; k <= opt.frames; ++k) {
              view.seed = 1000 * r + k;  // the same draws for every case: differences are the case's
              const SyntheticCloud cloud = render_surface_cloud(truth[k], model.boundary(), view);
              achieved = cloud.visible_fraction;
              cloud_points = static_cast<int>(cloud.cloud.size());
              last = registration.register_cloud(cloud.cloud, view.eye);
              frame_ms.push_back(last.total_ms);
              newton += last.newton_iterations;
              factorizations += last.factorizations;
              filter_ms += last.filter_ms / runs;
              correspondence_ms += last.correspondence_ms / runs;
              solve_ms += last.solve_ms / runs;
              diverged += last.step.status == StepResult::Status::Diverged;
              worst = std::max(worst, distance(target_positions(model), truth_targets[k]).max);
            }
            const std::vector<Eigen::Vector3d> registered = target_positions(model);
            const Errors after = distance(registered, truth_targets[opt.frames]);
            tre_mean += after.mean / opt.repeats;
            if (after.max > tre_max) tre_max = after.max, worst_target = names[after.worst];
            for (int i = 0; i < model.num_probes(); ++i)  // the probes are the tumour's points
              tumour += (registered[i] - truth_targets[opt.frames][i]).norm() / (model.num_probes() * opt.repeats);
            surface_error += boundary_error(model, truth[opt.frames]) / opt.repeats;
            rms += last.rms / opt.repeats;
          }
          const Errors before = distance(preoperative_targets, truth_targets[opt.frames]);
          std::vector<double> sorted = frame_ms;
          std::sort(sorted.begin(), sorted.end());
          out << noise << "," << visible << "," << achieved << "," << outliers << "," << opt.frames << ","
              << cloud_points << "," << last.used_points << "," << last.correspondences << "," << 1e3 * before.mean << ","
              << 1e3 * before.max << "," << 1e3 * tre_mean << "," << 1e3 * tre_max << "," << 1e3 * worst << ","
              << 1e3 * surface_error << "," << 1e3 * rms << "," << sorted[sorted.size() / 2] << "," << sorted.back()
              << "," << filter_ms << "," << correspondence_ms << "," << solve_ms << ","
              << static_cast<double>(newton) / runs << "," << static_cast<double>(factorizations) / runs << ","
              << diverged << "," << 1e3 * tumour << "," << worst_target << "\n"
              << std::flush;
          ++done;
          if (!opt.quiet)
            std::cerr << "case " << done << "/" << cases << ": noise " << 1e3 * noise << " mm, visible " << achieved
                      << ", outliers " << outliers << ": TRE " << 1e3 * tre_mean << " mm (max " << 1e3 * tre_max
                      << ", unregistered " << 1e3 * before.mean << "), " << sorted[sorted.size() / 2] << " ms/frame\n";
        }
  } catch (const std::exception& e) {
    std::cerr << "register_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
