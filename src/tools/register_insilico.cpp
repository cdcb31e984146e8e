// One-shot registration against a truth nobody here made (doc/registration.md, "In-silico case"):
// the Open-CAS in-silico liver (insilico_case.h), a model of its initial surface made by
// make_model (scripts/insilico_model.sh), each partial view of the deformed surface sampled as a
// dense cloud with sensor noise, registered in one shot (one_shot.h); the error at every interior
// node of the truth's volume, over all of them and the deepest tenth.
// Or a tracked stylus's strokes over its anterior side (stylus.h) instead of the views. With each
// target's covariance (OneShotRegistration::uncertainty): the share inside its 95% ellipsoid and
// the d^2 distribution against chi-square(3), over all targets and per depth band.
//   register_insilico --scene FILE [--data DIR] [--sensor views|stylus] [--views NAME,...]
//                     [--coverage C,...] [--noise M] [--spacing M] [--repeats R] [--set KEY=VALUE]...
//                     [--csv FILE] [--targets-csv FILE] [--quiet]
// Exit status: 0 done, 1 error, 2 bad command line, 3 the data are absent (skipped).
#include <algorithm>
#include <cmath>
#include <ctime>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "insilico_case.h"
#include "stylus.h"
#include "liver_sim/io/scene_files.h"
#include "liver_sim/registration/one_shot.h"
#include "one_shot_session.h"
#include "tool_io.h"
#include "liver_sim/registration/target_uncertainty.h"

namespace {

using namespace liver_sim;

struct Options {
  std::string scene, data, csv, targets_csv;
  std::vector<std::string> views;
  std::vector<double> coverages{0.2, 0.3, 0.44};
  bool stylus = false, quiet = false;
  double noise = 1e-3, spacing = 1e-3;
  int repeats = 1;
  OneShotOptions one_shot;
};

// The command line into `o`: the exit status when the tool is to stop, else nothing.
std::optional<int> parse(int argc, char** argv, Options* o) {
  namespace tool = liver_sim::tool;
  CLI::App app(
      "Registers a model of the Open-CAS in-silico liver in one shot to each partial view of its deformed\n"
      "surface (or to a stylus's strokes over it) and reports the error at every interior node of the\n"
      "truth, and how well the targets' covariances cover it (doc/registration.md).",
      "register_insilico");
  tool::describe(app,
                 "usage: register_insilico --scene FILE [--data DIR] [--sensor views|stylus] [--views NAME,...]\n"
                 "                         [--coverage C,...] [--noise M] [--spacing M] [--repeats R]\n"
                 "                         [--set KEY=VALUE]... [--csv FILE] [--targets-csv FILE] [--quiet]\n",
                 "Exit status: 0 done, 1 error, 2 bad command line, 3 the data are absent (the run is skipped).");
  o->data = insilico_folder("../shared/data/opencas-insilico");
  app.add_option("--scene", o->scene, "the model's scene (make_model on the case's initial-surface.stl); required")
      ->option_text("FILE")
      ->required();
  app.add_option("--data", o->data, "the case's folder (default: $LIVER_SIM_INSILICO, else\n../shared/data/opencas-insilico)")
      ->option_text("DIR");
  std::string sensor = "views";
  app.add_option("--sensor", sensor,
                 "each partial view sampled densely, or a tracked stylus swabbed\n"
                 "over the deformed surface's anterior side (stylus.h) (default views)")
      ->option_text("views|stylus")
      ->check(CLI::IsMember({"views", "stylus"}));
  tool::add_list(app, "--views", "NAME,...", o->views,
                 "partial views (the .stl files of --data; Open-CAS: xy, xz, xz-hemi,\nyz; default all)");
  tool::add_list(app, "--coverage", "C,...", o->coverages,
                 "stylus: the share of the surface its strokes cover, in (0, 1], a\nrun each (default 0.2,0.3,0.44)")
      ->check(tool::number("in (0, 1]", [](double c) { return c > 0 && c <= 1; }));
  app.add_option("--noise", o->noise, "sensor noise, standard deviation per coordinate (m, >= 0; default 0.001)")
      ->option_text("M")
      ->check(tool::non_negative());
  app.add_option("--spacing", o->spacing, "views: mean distance between the cloud's points (m, > 0; default 0.001)")
      ->option_text("M")
      ->check(tool::positive());
  app.add_option("--repeats", o->repeats, "clouds per view with other noise, >= 1 (default 1)")
      ->option_text("R")
      ->check(tool::at_least(1));
  add_one_shot_sets(app, &o->one_shot, "voxel_size,\nstart_gate, load_damping");
  app.add_option("--csv", o->csv, "one row per input and repeat (default: standard output)")->option_text("FILE");
  app.add_option("--targets-csv", o->targets_csv, "every target's error and covariance terms")->option_text("FILE");
  app.add_flag("--quiet", o->quiet, "no progress on standard error");
  app.callback([&] {
    o->stylus = sensor == "stylus";
  });
  return tool::parse(app, argc, argv);
}

// Depth bands of the calibration (m): shallow below the first, deep from the second.
constexpr double kShallow = 5e-3, kMiddle = 10e-3;

Eigen::VectorXd flat(const Eigen::MatrixX3d& V) {
  Eigen::VectorXd x(V.size());
  for (int i = 0; i < V.rows(); ++i) x.segment<3>(3 * i) = V.row(i).transpose();
  return x;
}

double surface_area(const SurfaceMesh& s) {
  double a = 0;
  for (int t = 0; t < s.F.rows(); ++t)
    a += 0.5 * (s.V.row(s.F(t, 1)) - s.V.row(s.F(t, 0))).cross(s.V.row(s.F(t, 2)) - s.V.row(s.F(t, 0))).norm();
  return a;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  if (const std::optional<int> status = parse(argc, argv, &opt)) return *status;
  const bool stylus = opt.stylus, quiet = opt.quiet;
  const double noise = opt.noise, spacing = opt.spacing;
  const std::string &data = opt.data, &csv = opt.csv, &targets_csv = opt.targets_csv;
  std::vector<std::string> views = opt.views;
  try {
    std::string why;
    const std::optional<InsilicoCase> truth = load_insilico_case(data, &why);
    if (!truth) {
      std::cerr << "register_insilico: skipped: " << why << "\n";
      return 3;
    }
    if (views.empty()) views = truth->view_names;
    const Scene scene = load_scene(opt.scene);
    const TetMesh mesh = load_scene_mesh(scene);
    const Eigen::VectorXd rest = LiverModel(mesh, scene).mechanics().rest_positions();
    std::vector<Eigen::Vector3d> start;
    for (int k : truth->targets) start.push_back(truth->initial.V.row(k).transpose());
    const std::vector<EmbeddedPoint> embedded = embed_points(mesh.T, rest, start);
    // What each registration sees: a view's surface sampled densely, or a stylus's strokes over
    // the deformed surface's anterior side at each coverage asked for.
    struct Input {
      std::string name;
      int repeat;
      double fraction;  // of the deformed surface's area: the view's, or the strokes' coverage
      pcl::PointCloud<pcl::PointXYZ> cloud;
    };
    std::vector<Input> inputs;
    const Eigen::MatrixX3i truth_boundary = boundary_triangles(truth->initial.T);
    const double full_area = surface_area(SurfaceMesh{truth->deformed, truth_boundary});
    for (int r = 0; r < opt.repeats; ++r) {
      if (stylus) {
        for (double c : opt.coverages) {
          StylusSweep sweep;
          sweep.coverage = c;
          sweep.noise = noise;
          sweep.seed = 1 + r;
          const StylusData data = swab_surface(flat(truth->deformed), truth_boundary, sweep);
          std::ostringstream name;
          name << "stylus-" << static_cast<int>(std::lround(100 * c)) << "%";
          inputs.push_back({name.str(), r, data.coverage, data.cloud});
        }
        continue;
      }
      for (const std::string& name : views) {
        const auto it = std::find(truth->view_names.begin(), truth->view_names.end(), name);
        if (it == truth->view_names.end()) throw std::invalid_argument("no view " + name);
        const SurfaceMesh& view = truth->views[it - truth->view_names.begin()];
        inputs.push_back({name, r, surface_area(view) / full_area, sample_surface(view, spacing, noise, 1 + r)});
      }
    }
    std::ofstream file, target_file;
    if (!csv.empty()) file.open(csv);
    std::ostream& out = csv.empty() ? std::cout : file;
    out << "view,repeat,fraction,noise_m,input_points,used_points,correspondences,coverage,rigid_rms_mm,rms_mm,"
           "load_total_n,unregistered_mean_mm,rigid_mean_mm,rigid_p95_mm,one_shot_mean_mm,one_shot_p95_mm,tre_mean_mm,tre_p95_mm,tre_max_mm,"
           "deep_mean_mm,deep_p95_mm,deep_max_mm,deep_from_mm,filter_ms,rigid_ms,deform_ms,total_ms,cpu_ms";
    for (const char* band : {"all", "shallow", "middle", "deep"})
      for (const char* what : {"targets", "inside_95", "d2_median", "ks"}) out << "," << band << "_" << what;
    out << "\n" << std::setprecision(6);
    if (!targets_csv.empty()) {
      target_file.open(targets_csv);
      target_file << "view,repeat,node,depth_mm,error_x_mm,error_y_mm,error_z_mm,d2,fit_sd_mm,model_sd_mm,displacement_mm,prior_mm\n"
                  << std::setprecision(6);
    }
    for (const Input& input : inputs) {
      // A session of its own for each input: no row depends on those before it.
      OneShotSession session(scene, opt.one_shot);
      session.set_targets(start);
      const std::clock_t c0 = std::clock();
      const OneShotSession::Result registered = session.register_cloud(input.cloud);
      const double cpu_ms = 1e3 * (std::clock() - c0) / CLOCKS_PER_SEC;
      const OneShotResult& result = registered.report.one_shot;
      const Eigen::Isometry3d rigid_to_cloud = result.rigid_alignment.inverse(), to_cloud = result.alignment.inverse();
      std::vector<double> error, unregistered, rigid, alone;
      std::vector<std::vector<double>> d2(4);  // all, then by depth band
      for (size_t i = 0; i < embedded.size(); ++i) {
        const Eigen::Vector3d truth_at = truth->deformed.row(truth->targets[i]).transpose();
        const Eigen::Vector3d e = registered.positions[i] - truth_at;
        error.push_back(e.norm());
        unregistered.push_back((start[i] - truth_at).norm());
        rigid.push_back((rigid_to_cloud * interpolate(mesh.T, rest, embedded[i]) - truth_at).norm());
        alone.push_back((to_cloud * interpolate(mesh.T, result.positions, embedded[i]) - truth_at).norm());
        const OneShotRegistration::PointUncertainty& u = registered.uncertainty[i];
        const Eigen::Matrix3d covariance = u.total();
        const double m = e.dot(covariance.ldlt().solve(e));
        const double depth = truth->depth[i];
        d2[0].push_back(m);
        d2[depth < kShallow ? 1 : depth < kMiddle ? 2 : 3].push_back(m);
        if (target_file.is_open())
          target_file << input.name << "," << input.repeat << "," << truth->targets[i] << "," << 1e3 * depth << ","
                      << 1e3 * e.x() << "," << 1e3 * e.y() << "," << 1e3 * e.z() << "," << m << ","
                      << 1e3 * std::sqrt(u.fit.trace() / 3) << "," << 1e3 * std::sqrt(u.model.trace() / 3) << ","
                      << 1e3 * u.displacement.norm() << "," << 1e3 * u.prior.norm() << "\n";
      }
      const TreSummary s = summarise_tre(error, truth->depth), un = summarise_tre(unregistered, truth->depth),
                       g = summarise_tre(rigid, truth->depth), o = summarise_tre(alone, truth->depth);
      out << input.name << "," << input.repeat << "," << input.fraction << "," << noise << "," << result.input_points << ","
          << result.used_points << "," << result.correspondences << "," << result.coverage << "," << 1e3 * result.rigid_rms
          << "," << 1e3 * result.rms << "," << result.load_total << "," << 1e3 * un.mean << "," << 1e3 * g.mean << ","
          << 1e3 * g.p95 << "," << 1e3 * o.mean << "," << 1e3 * o.p95 << "," << 1e3 * s.mean << "," << 1e3 * s.p95 << "," << 1e3 * s.max << "," << 1e3 * s.deep_mean << ","
          << 1e3 * s.deep_p95 << "," << 1e3 * s.deep_max << "," << 1e3 * s.deep_from << "," << result.filter_ms << ","
          << result.rigid_ms << "," << result.deform_ms << "," << result.total_ms << "," << cpu_ms;
      for (const std::vector<double>& band : d2) {
        const Calibration c = calibration(band);
        out << "," << c.count << "," << c.inside_95 << "," << c.median << "," << c.ks;
      }
      out << "\n" << std::flush;
      if (!quiet)
        std::cerr << input.name << " #" << input.repeat << ": TRE mean " << 1e3 * s.mean << " mm, p95 " << 1e3 * s.p95
                  << ", max " << 1e3 * s.max << ", deepest 10% " << 1e3 * s.deep_mean << " (rigid " << 1e3 * g.mean << " / "
                  << 1e3 * g.p95 << "); inside 95% " << calibration(d2[0]).inside_95 << "; " << cpu_ms << " ms CPU\n";
    }
  } catch (const std::exception& e) {
    std::cerr << "register_insilico: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
