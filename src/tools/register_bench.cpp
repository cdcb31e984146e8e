// Registration benchmark without hardware (doc/registration.md). A ground truth deforms over the
// frames under a surgical load (scenarios.h: a retractor's lift, an instrument's pressure, the
// diaphragm, the pneumoperitoneum), ramped from 0 to full; each frame a sensor renders the
// truth's visible surface and the model registers the cloud, warm-started from the last frame.
// The truth is either
//   - the model's own scene (the inverse crime: same mesh, material and attachments), or
//   - an independent truth (--truth-scene, scripts/make_truth_phantom.py): a finer mesh of the
//     same anatomy, another material, an attachment the model does not know; its targets are
//     the same material points embedded in its own tetrahedra.
// The sensor is a depth camera (depth_camera.h: noise growing with depth squared, holes at
// grazing angles and depth edges, instruments in view, blood, a partial field of view) or the
// surface sampler (render_surface_cloud: uniform samples, Gaussian noise, uniform outliers).
// Reported per case: the target registration error (TRE) of the tumour probes and vessel
// bifurcations at the last frame (mean, 95th percentile, max; tumour and bifurcations apart),
// before and after registration, and the time per frame.
//   register_bench --scene FILE [--set K=V]... [--truth-scene FILE] [--scenario NAME,...]
//                  [--sensor depth|surface] [--frames N] [--repeats R] [--noise M,...]
//                  [--visible FRACTION,...] [--outliers FRACTION,...] [--stiffness SCALE,...]
//                  [--attachments model|truth] [--supports estimate|off] [--camera-motion DEG]
//                  [--csv FILE] [--targets-csv FILE] [--quiet]
// Every combination of the lists is one CSV row (standard output or --csv), over R runs with
// other random clouds; --targets-csv writes every target's error at the last frame of every run.
// Progress on stderr. Pin it (taskset -c 0) for timings.
#include <algorithm>
#include <cmath>
#include <ctime>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "depth_camera.h"
#include "liver_sim/simulation/liver_model.h"
#include "liver_sim/registration/registration.h"
#include "liver_sim/registration/target_uncertainty.h"
#include "liver_sim/session/tracking_session.h"
#include "scenarios.h"
#include "tool_io.h"

namespace {

using namespace liver_sim;

struct Options {
  std::string scene, truth_scene, csv, targets_csv;
  std::vector<std::string> overrides;
  std::vector<std::string> scenarios{"lift"};
  bool depth_sensor = true;
  int frames = 10;
  int repeats = 1;  // runs of each case with other random draws
  std::vector<double> noise{1e-3}, visible{0.3}, outliers{0.0}, stiffness{1.0};
  bool truth_attachments = false;
  bool estimate_supports = true;  // hold the scene's candidate supports the clouds call for
  double camera_motion = 0;  // deg
  bool quiet = false;
};

// The command line into `o`: the exit status when the tool is to stop, else nothing.
std::optional<int> parse(int argc, char** argv, Options* o) {
  namespace tool = liver_sim::tool;
  CLI::App app(
      "Registers the model to synthetic clouds of a deforming truth, frame by frame; one CSV row per\n"
      "combination of the lists (target registration errors before and after, time per frame).",
      "register_bench");
  tool::describe(app,
                 "usage: register_bench --scene FILE [--set K=V]... [--truth-scene FILE] [--scenario NAME,...]\n"
                 "                      [--sensor depth|surface] [--frames N] [--repeats R] [--noise M,...]\n"
                 "                      [--visible FRACTION,...] [--outliers FRACTION,...] [--stiffness SCALE,...]\n"
                 "                      [--attachments model|truth] [--supports estimate|off] [--camera-motion DEG]\n"
                 "                      [--csv FILE] [--targets-csv FILE] [--quiet]\n");
  // An option of two words, `flag` set when it is `yes`.
  auto choice = [&](const std::string& name, const std::string& a, const std::string& b, const std::string& yes,
                    bool& flag, const std::string& what) {
    app.add_option_function<std::string>(name, [&flag, yes](const std::string& v) { flag = v == yes; }, what)
        ->option_text(a + "|" + b)
        ->check(CLI::IsMember({a, b}));
  };
  std::string scenarios;
  for (const std::string& s : surgical_scenario_names()) scenarios += (scenarios.empty() ? "" : ", ") + s;
  app.add_option("--scene", o->scene, "the model's YAML scene (README, 'Scene format'); required")
      ->option_text("FILE")
      ->required();
  tool::add_overrides(app, o->overrides, "override a scalar of the model's scene (repeatable)");
  app.add_option("--truth-scene", o->truth_scene,
                 "an independent truth (scripts/make_truth_phantom.py); default: the\n"
                 "model's own scene (the inverse crime)")
      ->option_text("FILE");
  tool::add_list(app, "--scenario", "NAME,...", o->scenarios, "the truth's load: " + scenarios + " (default lift)")
      ->check(CLI::IsMember(surgical_scenario_names()));
  choice("--sensor", "depth", "surface", "depth", o->depth_sensor,
         "a depth camera (occlusion, holes, instruments, blood) or uniform\n"
         "surface samples (default depth)");
  app.add_option("--frames", o->frames, "frames over which the load ramps to full, >= 1 (default 10)")
      ->option_text("N")
      ->check(tool::at_least(1));
  app.add_option("--repeats", o->repeats, "runs of each case with other random clouds, >= 1 (default 1)")
      ->option_text("R")
      ->check(tool::at_least(1));
  tool::add_list(app, "--noise", "M,...", o->noise,
                 "depth noise at 25 cm (m, standard deviation, >= 0; default 0.001)")
      ->check(tool::non_negative());
  tool::add_list(app, "--visible", "FRACTION,...", o->visible,
                 "share of the surface area in the sensor's view, in (0, 1] (default 0.3)")
      ->check(tool::number("in (0, 1]", [](double f) { return f > 0 && f <= 1; }));
  tool::add_list(app, "--outliers", "FRACTION,...", o->outliers,
                 "surface sensor: share of uniform outlier points, in [0, 1] (default 0)")
      ->check(tool::number("in [0, 1]", [](double f) { return f >= 0 && f <= 1; }));
  tool::add_list(app, "--stiffness", "SCALE,...", o->stiffness,
                 "the model's parenchyma Young's modulus times SCALE, > 0 (default 1)")
      ->check(tool::positive());
  choice("--attachments", "model", "truth", "truth", o->truth_attachments,
         "the model keeps its own attachments or gets the truth's (default model)");
  choice("--supports", "estimate", "off", "estimate", o->estimate_supports,
         "hold the candidate supports the clouds call for, or never (default estimate)");
  app.add_option("--camera-motion", o->camera_motion,
                 "the camera sways by +-DEG about the vertical through the liver (default 0)")
      ->option_text("DEG")
      ->check(tool::any_number());
  app.add_option("--csv", o->csv, "write the rows to FILE instead of standard output")->option_text("FILE");
  app.add_option("--targets-csv", o->targets_csv, "write every target's error at the last frame of every run")
      ->option_text("FILE");
  app.add_flag("--quiet", o->quiet, "no progress on standard error");
  return tool::parse(app, argc, argv);
}

std::vector<Eigen::Vector3d> target_positions(const LiverModel& m) {
  std::vector<Eigen::Vector3d> p;
  for (const TrackedTarget& t : tracked_targets(m)) p.push_back(t.position);
  return p;
}

// The truth over the frames: positions, boundary, targets; frame 0 is the scene at rest under
// its own loads (the pre-operative state), frame k has the scenario's loads at k / frames.
struct Truth {
  TetMesh mesh;
  Eigen::MatrixX3i boundary;
  std::vector<Eigen::VectorXd> x;
  std::vector<std::vector<Eigen::Vector3d>> targets;
  std::vector<std::string> names;
  std::vector<bool> tumour;  // per target: a probe (the tumour), else a bifurcation
};

Truth make_truth(const Scene& scene, const SurgicalScenario& scenario, int frames, bool quiet) {
  Truth truth;
  truth.mesh = load_scene_mesh(scene);
  Scene s = scene;
  s.solver.mode = SolverOptions::Mode::Static;
  s.solver.strategy = SolverOptions::Strategy::NewtonKrylov;
  s.solver.tolerance = 1e-9;
  s.solver.max_iterations = 100;
  const size_t scene_loads = s.loads.size();
  for (int k = 0; k <= frames; ++k) {
    s.loads.resize(scene_loads);
    for (const LoadOptions& l : scaled(scenario.loads, static_cast<double>(k) / frames)) s.loads.push_back(l);
    LiverModel m(truth.mesh, s);
    if (k > 0) m.set_positions(truth.x.back());  // continuation from the last frame
    const StepResult r = m.step();
    if (!r.converged())
      throw std::runtime_error("truth frame " + std::to_string(k) + " of " + scenario.name + " did not converge: " + r.message);
    truth.x.push_back(m.positions());
    truth.targets.push_back(target_positions(m));
    if (k == 0) {
      truth.boundary = m.boundary();
      for (const TrackedTarget& t : tracked_targets(m)) {
        truth.names.push_back(t.name);
        truth.tumour.push_back(t.kind == TrackedTarget::Kind::Probe);
      }
    }
    if (!quiet) std::cerr << "\rtruth " << scenario.name << " " << k << "/" << frames << std::flush;
  }
  if (!quiet) std::cerr << "\n";
  return truth;
}

// The springs' energy at the model's state (J): how hard the cloud pulls against the model.
double spring_energy(const LiverModel& m) {
  double e = 0;
  for (const SurfaceTarget& t : m.surface_targets()) e += 0.5 * t.stiffness * t.stretch(m.positions(), m.boundary()).squaredNorm();
  return e;
}

struct Stats {
  double mean = 0, p95 = 0, max = 0;
};
Stats stats(std::vector<double> v) {
  Stats s;
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  for (double d : v) s.mean += d / v.size();
  // Nearest rank.
  s.p95 = v[std::min(v.size() - 1, static_cast<size_t>(std::ceil(0.95 * v.size())) - 1)];
  s.max = v.back();
  return s;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  if (const std::optional<int> status = parse(argc, argv, &opt)) return *status;
  try {
    const Scene scene = load_scene(opt.scene, opt.overrides);
    const TetMesh mesh = load_scene_mesh(scene);
    const Scene truth_scene = opt.truth_scene.empty() ? scene : load_scene(opt.truth_scene);
    const bool inverse_crime = opt.truth_scene.empty();

    std::ofstream file, target_file;
    if (!opt.csv.empty()) file.open(opt.csv);
    std::ostream& out = opt.csv.empty() ? std::cout : file;
    out << "truth,scenario,sensor,noise_m,visible_request,visible_fraction,returned_fraction,outlier_fraction,stiffness_scale,"
           "stiffness_ratio,attachments,frames,cloud_points,used_points,correspondences,coverage,"
           "tre_unregistered_mean_mm,tre_unregistered_max_mm,tre_mean_mm,tre_p95_mm,tre_max_mm,tumour_mean_mm,"
           "tumour_p95_mm,tumour_max_mm,bifurcation_mean_mm,bifurcation_p95_mm,bifurcation_max_mm,"
           "frame_median_ms,frame_max_ms,filter_ms,correspondence_ms,solve_ms,newton_per_frame,diverged,worst_target,"
           "inside_95,radius_95_mean_mm,spring_energy_uj,analysis_ms,supports,tissue_factor,hidden_load_n,frame_cpu_median_ms,analysis_cpu_ms\n";
    out << std::setprecision(6);
    if (!opt.targets_csv.empty()) {
      target_file.open(opt.targets_csv);
      target_file << "truth,scenario,noise_m,visible_request,stiffness_scale,repeat,target,tumour,unregistered_mm,"
                     "error_x_mm,error_y_mm,error_z_mm,mahalanobis_squared";
      // The covariance (mm^2) and its parts: xx, yy, zz, xy, xz, yz each.
      for (const char* part : {"total", "forces", "stiffness", "noise"})
        for (const char* entry : {"xx", "yy", "zz", "xy", "xz", "yz"}) target_file << "," << part << "_" << entry;
      target_file << "\n" << std::setprecision(6);
    }
    const std::string truth_name = inverse_crime ? "model" : "independent";
    for (const std::string& scenario_name : opt.scenarios) {
      const SurgicalScenario truth_scenario = surgical_scenario(scenario_name, load_scene_mesh(truth_scene));
      const Truth truth = make_truth(truth_scene, truth_scenario, opt.frames, opt.quiet);
      const int last = opt.frames;
      for (double stiffness : opt.stiffness) {
        Scene model_scene = scene;
        model_scene.parenchyma.young_modulus *= stiffness;
        if (opt.truth_attachments) model_scene.fixed = truth_scene.fixed;
        if (opt.truth_attachments || !opt.estimate_supports) model_scene.registration.candidate_supports.clear();
        // The pre-operative model: its own scene at equilibrium (the inverse crime: the truth's
        // frame 0 exactly). The session starts from it; its analyses run in the frame that
        // registered the cloud, after every cloud (the node's, at most once a period, on a thread).
        SessionOptions session_options;
        session_options.analysis = RegistrationAnalysis::Placement::InFrame;
        session_options.analysis_period = 0;
        {
          Scene tight = model_scene;
          tight.solver.mode = SolverOptions::Mode::Static;
          tight.solver.tolerance = 1e-10;
          tight.solver.max_iterations = 100;
          LiverModel rest(mesh, tight);
          const StepResult r = rest.step();
          if (!r.converged()) throw std::runtime_error("the pre-operative model did not converge: " + r.message);
          session_options.start = rest.positions();
        }
        TrackingSession session(mesh, model_scene, session_options);
        const LiverModel& model = session.model();
        const SurfaceRegistration& registration = session.registration();
        const Eigen::VectorXd preoperative = model.positions();
        const std::vector<Eigen::Vector3d> preoperative_targets = target_positions(model);
        if (preoperative_targets.size() != truth.names.size())
          throw std::runtime_error("the model tracks " + std::to_string(preoperative_targets.size()) + " targets, the truth " +
                                   std::to_string(truth.names.size()));
        std::vector<double> unregistered;
        for (size_t i = 0; i < truth.names.size(); ++i)
          unregistered.push_back((preoperative_targets[i] - truth.targets[last][i]).norm());
        const Stats before = stats(unregistered);
        const double ratio = model_scene.parenchyma.young_modulus / truth_scene.parenchyma.young_modulus;
        for (double noise : opt.noise)
          for (double visible : opt.visible)
            for (double outliers : opt.outliers) {
              std::vector<double> frame_ms, frame_cpu_ms, all, tumour, bifurcation, radius;
              double inside = 0, energy = 0, analysis_ms = 0, analysis_cpu_ms = 0;
              std::string held;
              double achieved = 0, returned = 0, filter_ms = 0, correspondence_ms = 0, solve_ms = 0, coverage = 0;
              double outlier_share = 0, tissue_factor = 0, hidden_load = 0;
              int newton = 0, diverged = 0, cloud_points = 0;
              const int runs = opt.frames * opt.repeats;
              RegistrationFrame frame;
              std::string worst_target;
              double worst = -1;
              for (int r = 0; r < opt.repeats; ++r) {
                session.submit(Reset{preoperative});
                std::vector<TargetUncertainty::Covariance> covariance;
                for (int k = 1; k <= opt.frames; ++k) {
                  const unsigned seed = 1000 * r + k;  // the same draws for every case: differences are the case's
                  // The camera at the front, swaying by +-camera_motion about the vertical through the liver.
                  const double sway = opt.camera_motion * M_PI / 180 * std::sin(2 * M_PI * k / opt.frames);
                  const Eigen::AngleAxisd turn(sway, Eigen::Vector3d::UnitZ());
                  pcl::PointCloud<pcl::PointXYZ> cloud;
                  Eigen::Vector3d eye;
                  if (opt.depth_sensor) {
                    DepthCamera camera = front_depth_camera(truth.x[0]);
                    camera.eye = camera.target + turn * (camera.eye - camera.target);
                    camera.visible_fraction = visible;
                    camera.depth_noise = noise;
                    camera.seed = seed;
                    const DepthCloud c = render_depth_cloud(truth.x[k], truth.boundary,
                                                            instrument_shafts(truth_scenario, truth.x[k], truth.boundary), camera);
                    cloud = c.cloud;
                    achieved = c.visible_fraction;
                    returned = c.returned_fraction;
                    outlier_share = c.cloud.empty() ? 0.0 : static_cast<double>(c.instrument_points) / c.cloud.size();
                    eye = camera.eye;
                  } else {
                    CameraView view = front_view(truth.x[0]);
                    view.eye = view.target + turn * (view.eye - view.target);
                    view.visible_fraction = visible;
                    view.noise = noise;
                    view.outlier_fraction = outliers;
                    view.seed = seed;
                    const SyntheticCloud c = render_surface_cloud(truth.x[k], truth.boundary, view);
                    cloud = c.cloud;
                    achieved = returned = c.visible_fraction;
                    outlier_share = outliers;
                    eye = view.eye;
                  }
                  cloud_points = static_cast<int>(cloud.size());
                  // The analyses after every cloud: which candidate supports to hold, the tissue's
                  // stiffness, the hidden loads; the targets' covariances at the last.
                  if (k == opt.frames) session.want_covariances();
                  session.submit(Cloud{std::move(cloud), eye, 0});
                  // CPU time besides the wall clock: the cost on a core shared with other jobs.
                  const std::clock_t c0 = std::clock();
                  const FrameReport report = session.advance();
                  const std::clock_t c1 = std::clock();
                  if (!report.cloud) throw std::runtime_error("frame " + std::to_string(k) + ": the cloud was refused: " + session.notices().last_refusal());
                  frame = *report.cloud;
                  frame_cpu_ms.push_back(1e3 * (c1 - c0) / CLOCKS_PER_SEC - 1e3 * report.analysis.cpu_time);
                  if (k == opt.frames) covariance = session.covariances();
                  analysis_ms += 1e3 * report.analysis.wall_time / runs;
                  analysis_cpu_ms += 1e3 * report.analysis.cpu_time / runs;
                  frame_ms.push_back(frame.total_ms);
                  newton += frame.newton_iterations;
                  filter_ms += frame.filter_ms / runs;
                  correspondence_ms += frame.correspondence_ms / runs;
                  solve_ms += frame.solve_ms / runs;
                  coverage += frame.coverage / runs;
                  diverged += frame.step.status == StepResult::Status::Diverged;
                }
                const std::vector<Eigen::Vector3d> registered = target_positions(model);
                if (covariance.size() != registered.size())
                  throw std::runtime_error("no target covariances at the last frame: " + session.last_step().message);
                energy += spring_energy(model) / opt.repeats;
                tissue_factor += model.stiffness_scale() / opt.repeats;
                hidden_load += registration.hidden_load_total() / opt.repeats;
                held.clear();
                for (size_t c = 0; c < registration.supports_held().size(); ++c) {
                  std::ostringstream gain;
                  gain << std::setprecision(2) << registration.support_gains()[c];
                  held += (c ? " " : "") + std::string(registration.supports_held()[c] ? "held:" : "") + gain.str();
                }
                for (size_t i = 0; i < registered.size(); ++i) {
                  const Eigen::Vector3d e = registered[i] - truth.targets[last][i];
                  // Inside the 95% ellipsoid: e^T C^-1 e below the chi-square quantile of 3 DOF.
                  const double d2 = e.dot(covariance[i].total.ldlt().solve(e));
                  inside += (d2 <= kChiSquare3At95) / static_cast<double>(registered.size() * opt.repeats);
                  radius.push_back(ellipsoid_95(covariance[i].total).semi_axes.z());
                  all.push_back(e.norm());
                  (truth.tumour[i] ? tumour : bifurcation).push_back(e.norm());
                  if (e.norm() > worst) worst = e.norm(), worst_target = truth.names[i];
                  if (target_file.is_open())
                    target_file << truth_name << "," << scenario_name << "," << noise << "," << visible << "," << stiffness << ","
                                << r << "," << truth.names[i] << "," << truth.tumour[i] << "," << 1e3 * unregistered[i] << ","
                                << 1e3 * e.x() << "," << 1e3 * e.y() << "," << 1e3 * e.z() << "," << d2;
                  for (const Eigen::Matrix3d* c : {&covariance[i].total, &covariance[i].forces, &covariance[i].stiffness,
                                                   &covariance[i].noise})
                    for (const auto& [a, b] : {std::pair{0, 0}, {1, 1}, {2, 2}, {0, 1}, {0, 2}, {1, 2}})
                      target_file << "," << 1e6 * (*c)(a, b);
                  target_file << "\n";
                }
              }
              const Stats a = stats(all), t = stats(tumour), b = stats(bifurcation);
              std::vector<double> sorted = frame_ms;
              std::sort(sorted.begin(), sorted.end());
              out << truth_name << "," << scenario_name << "," << (opt.depth_sensor ? "depth" : "surface") << "," << noise
                  << "," << visible << "," << achieved << "," << returned << "," << outlier_share << "," << stiffness << "," << ratio << ","
                  << (opt.truth_attachments ? "truth" : "model") << "," << opt.frames << "," << cloud_points << ","
                  << frame.used_points << "," << frame.correspondences << "," << coverage << "," << 1e3 * before.mean << ","
                  << 1e3 * before.max << "," << 1e3 * a.mean << "," << 1e3 * a.p95 << "," << 1e3 * a.max << ","
                  << 1e3 * t.mean << "," << 1e3 * t.p95 << "," << 1e3 * t.max << "," << 1e3 * b.mean << "," << 1e3 * b.p95
                  << "," << 1e3 * b.max << "," << sorted[sorted.size() / 2] << "," << sorted.back() << "," << filter_ms << ","
                  << correspondence_ms << "," << solve_ms << "," << static_cast<double>(newton) / runs << "," << diverged
                  << "," << worst_target << "," << inside << "," << 1e3 * stats(radius).mean << "," << 1e6 * energy << "," << analysis_ms << "," << held << "," << tissue_factor << "," << hidden_load << "," << median(frame_cpu_ms) << "," << analysis_cpu_ms << "\n"
                  << std::flush;
              if (!opt.quiet)
                std::cerr << truth_name << " " << scenario_name << ": noise " << 1e3 * noise << " mm, visible " << achieved
                          << ", stiffness x" << stiffness << " (ratio " << ratio << "): TRE " << 1e3 * a.mean << " mm (p95 "
                          << 1e3 * a.p95 << ", max " << 1e3 * a.max << ", unregistered " << 1e3 * before.mean << "), "
                          << sorted[sorted.size() / 2] << " ms/frame\n";
            }
      }
    }
  } catch (const std::exception& e) {
    std::cerr << "register_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
