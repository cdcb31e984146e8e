// Registers a liver model to one intra-operative surface or point cloud and writes where the
// targets are now, with their covariances: any public case in one command (doc/registration.md,
// "One-shot registration"). The path is the node's for its first cloud (one_shot_session.h).
//   register --scene FILE --surface FILE --targets FILE --out FILE [--unit mm|cm|m]
//            [--viewpoint X,Y,Z] [--spacing D] [--set KEY=VALUE]...
// A JSON summary on standard output. Exit status: 0 done, 1 bad input (one line naming the file
// and the defect), 2 bad command line.
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>

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
#include "liver_sim/io/file_names.h"
#include "liver_sim/io/surface_io.h"
#include "liver_sim/scene/scene.h"
#include "one_shot_session.h"
#include "tool_io.h"

namespace {

using namespace liver_sim;

struct BadInput : std::runtime_error {
  using std::runtime_error::runtime_error;
};

std::vector<double> numbers(const std::string& s) {
  std::vector<double> v;
  std::stringstream in(s);
  std::string part;
  while (std::getline(in, part, ',')) {
    size_t used = 0;
    v.push_back(std::stod(part, &used));
    if (part.find_first_not_of(" \t\r", used) != std::string::npos) throw std::invalid_argument("not a number: " + part);
  }
  return v;
}

// The data as points (m): a surface sampled, or a cloud as it is.
pcl::PointCloud<pcl::PointXYZ> read_data(const std::string& path, double scale, double spacing) {
  const std::string ext = file_extension(path);
  pcl::PointCloud<pcl::PointXYZ> cloud;
  if (ext == "pcd") {
    if (pcl::io::loadPCDFile(path, cloud) != 0) throw BadInput(path + ": not a readable PCD file");
  } else {
    try {
      return sample_surface(read_surface(path, scale), spacing, 0.0, 1);
    } catch (const MeshError& e) {
      if (ext != "ply") throw BadInput(e.what());
      if (pcl::io::loadPLYFile(path, cloud) != 0) throw BadInput(path + ": neither a surface nor a point cloud PLY");
    }
  }
  for (pcl::PointXYZ& p : cloud) p.getVector3fMap() *= static_cast<float>(scale);
  if (cloud.empty()) throw BadInput(path + ": no point");
  return cloud;
}

struct Target {
  std::string name;
  Eigen::Vector3d point;
};

std::vector<Target> read_targets(const std::string& path, double scale) {
  std::ifstream in(path);
  if (!in) throw BadInput(path + ": cannot open");
  std::vector<Target> targets;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    line = line.substr(0, line.find('#'));
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const size_t comma = line.find(',');
    std::vector<double> xyz;
    try {
      if (comma == std::string::npos) throw std::invalid_argument("no comma");
      xyz = numbers(line.substr(comma + 1));
    } catch (const std::exception&) {
      if (targets.empty() && number == 1) continue;  // a header
      throw BadInput(path + ":" + std::to_string(number) + ": expected name,x,y,z");
    }
    if (xyz.size() != 3 || !std::isfinite(xyz[0]) || !std::isfinite(xyz[1]) || !std::isfinite(xyz[2]))
      throw BadInput(path + ":" + std::to_string(number) + ": expected name,x,y,z with three finite numbers");
    targets.push_back({line.substr(0, comma), scale * Eigen::Vector3d(xyz[0], xyz[1], xyz[2])});
  }
  if (targets.empty()) throw BadInput(path + ": no target");
  return targets;
}

// The one call that registers (one_shot_session.h).
OneShotSession::Result register_once(const Scene& scene, const OneShotOptions& options, const std::vector<Target>& targets,
                                     const pcl::PointCloud<pcl::PointXYZ>& cloud,
                                     const std::optional<Eigen::Vector3d>& viewpoint) {
  OneShotSession session(scene, options);
  std::vector<Eigen::Vector3d> points;
  for (const Target& t : targets) points.push_back(t.point);
  session.set_targets(points);
  return session.register_cloud(cloud, viewpoint);
}

struct Options {
  std::string scene, surface, targets, out;
  double scale = 1e-3;
  std::optional<Eigen::Vector3d> viewpoint;  // m
  double spacing = 1e-3;                     // m
  OneShotOptions one_shot;
};

// The command line into `o`: the exit status when the tool is to stop, else nothing.
std::optional<int> parse(int argc, char** argv, Options* o) {
  namespace tool = liver_sim::tool;
  CLI::App app(
      "Registers the scene's model in one shot to an intra-operative surface or point cloud of the organ,\n"
      "deformed and moved as it may be, its attachments unknown, and writes where the targets are now\n"
      "(doc/registration.md). Lengths are in --unit, in the frame of the pre-operative model (targets)\n"
      "and of the intra-operative data (surface, viewpoint, output).",
      "register");
  tool::describe(app,
                 "usage: register --scene FILE --surface FILE --targets FILE --out FILE [--unit mm|cm|m]\n"
                 "                [--viewpoint X,Y,Z] [--spacing D] [--set KEY=VALUE]...\n",
                 "A JSON summary on standard output.\n"
                 "Exit status: 0 done, 1 bad input (one line naming the file and the defect), 2 bad command line.");
  app.add_option("--scene", o->scene, "the model's scene (README, 'Scene format'; make_model writes one);\nrequired")
      ->option_text("FILE")
      ->required();
  app.add_option("--surface", o->surface,
                 "the intra-operative data: a surface (.stl, .obj, .vtk, or .ply with\n"
                 "faces), sampled --spacing apart, or a point cloud (.ply without faces,\n.pcd); required")
      ->option_text("FILE")
      ->required();
  app.add_option("--targets", o->targets,
                 "CSV, a target per line: name,x,y,z (pre-operative model); '#' starts a\n"
                 "comment; a first line that is not numbers is a header; required")
      ->option_text("FILE")
      ->required();
  app.add_option("--out", o->out,
                 "CSV written: name,x,y,z, their standard deviation sd (root of the\n"
                 "covariance's trace over 3) and the covariance xx,yy,zz,xy,xz,yz (unit^2);\nrequired")
      ->option_text("FILE")
      ->required();
  std::string unit = "mm";
  app.add_option("--unit", unit, "length unit of the files and the viewpoint (default mm)")
      ->option_text("mm|cm|m")
      ->check(CLI::IsMember({"mm", "cm", "m"}));
  std::vector<double> viewpoint;
  app.add_option("--viewpoint", viewpoint, "the sensor's origin in the data's frame, when known (its normals face it)")
      ->option_text("X,Y,Z")
      ->delimiter(',')
      ->expected(3)
      ->allow_extra_args(false)
      ->check(tool::any_number());
  double spacing = 1;
  app.add_option("--spacing", spacing, "surface input: mean distance between its samples, > 0 (--unit; default 1 mm)")
      ->option_text("D")
      ->check(tool::positive());
  add_one_shot_sets(app, &o->one_shot, "start_gate,\nload_damping, foundation");
  app.callback([&] {
    o->scale = unit == "mm" ? 1e-3 : unit == "cm" ? 1e-2 : 1.0;
    o->spacing = app.count("--spacing") ? spacing * o->scale : 1e-3;
    if (!viewpoint.empty()) o->viewpoint = o->scale * Eigen::Vector3d(viewpoint[0], viewpoint[1], viewpoint[2]);
  });
  return tool::parse(app, argc, argv);
}

}  // namespace

int main(int argc, char** argv) {
  namespace tool = liver_sim::tool;
  Options opt;
  if (const std::optional<int> status = parse(argc, argv, &opt)) return *status;
  const double scale = opt.scale;
  try {
    const Scene scene = load_scene(opt.scene);
    const std::vector<Target> targets = read_targets(opt.targets, scale);
    const pcl::PointCloud<pcl::PointXYZ> cloud = read_data(opt.surface, scale, opt.spacing);
    const std::clock_t c0 = std::clock();
    const OneShotSession::Result result = register_once(scene, opt.one_shot, targets, cloud, opt.viewpoint);
    const double cpu_s = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
    std::ofstream out(opt.out);
    if (!out) throw BadInput(opt.out + ": cannot open for writing");
    out << "name,x,y,z,sd,xx,yy,zz,xy,xz,yz\n" << std::setprecision(9);
    for (size_t i = 0; i < targets.size(); ++i) {
      const Eigen::Vector3d p = result.positions[i] / scale;
      const Eigen::Matrix3d c = result.uncertainty[i].total() / (scale * scale);
      out << targets[i].name << "," << p.x() << "," << p.y() << "," << p.z() << "," << std::sqrt(c.trace() / 3) << ","
          << c(0, 0) << "," << c(1, 1) << "," << c(2, 2) << "," << c(0, 1) << "," << c(0, 2) << "," << c(1, 2) << "\n";
    }
    if (!out) throw BadInput(opt.out + ": write failed");
    const OneShotResult& r = result.report.one_shot;
    nlohmann::ordered_json summary;
    summary["targets"] = targets.size();
    summary["input_points"] = r.input_points;
    summary["used_points"] = r.used_points;
    summary["correspondences"] = r.correspondences;
    summary["coverage"] = r.coverage;
    summary["rigid_rms_m"] = r.rigid_rms;
    summary["rms_m"] = r.rms;
    summary["load_total_n"] = r.load_total;
    summary["processor_s"] = cpu_s;  // with the model's construction
    tool::print_json(std::cout, summary);
  } catch (const std::exception& e) {
    std::cerr << "register: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
