// Scene files (YAML): mesh, materials, boundary conditions, loads, solver, probes, vessels,
// instruments and contact.
// The format is documented in README.md ("Scene format").
#pragma once

#include <Eigen/Core>
#include <stdexcept>
#include <string>
#include <vector>

#include "liver_sim/scene/options.h"

namespace liver_sim {

class SceneError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct MeshSource {
  std::string file;  // absolute, or relative to the scene file's folder after loading; empty: box
  double scale = 1.0;  // file units -> m
  Eigen::Vector3d box_size = Eigen::Vector3d::Zero();  // m
  Eigen::Vector3i box_divisions = Eigen::Vector3i::Zero();
};

struct Scene {
  MeshSource mesh;
  ParenchymaOptions parenchyma;
  CapsuleOptions capsule;
  std::vector<Region> fixed;
  std::vector<LoadOptions> loads;
  SolverOptions solver;
  std::vector<ProbeOptions> probes;
  std::vector<VesselOptions> vessels;  // files resolved like the mesh file
  std::vector<InstrumentOptions> instruments;
  ContactOptions contact;
  RegistrationOptions registration;
};

// Parses a scene file. `overrides` are "dotted.key=value" strings applied to the YAML tree
// before it is read (sequence items by index: "loads.0.value=-3000"). Unknown keys, wrong
// types and invalid values throw SceneError whose message names the file and the key.
// A relative mesh file is resolved against the scene file's folder.
Scene load_scene(const std::string& path, const std::vector<std::string>& overrides = {});

// The text of a file in the scene format (a scene, instruments). Throws SceneError naming the
// file when it cannot be opened or is larger than 1 MiB.
std::string read_scene_text(const std::string& path);

// Instruments alone, from a YAML file with an `instruments:` list in the scene format (a
// benchmark's scenario added to a scene). Throws SceneError naming the file and the key.
std::vector<InstrumentOptions> load_instruments(const std::string& path);

// Same as load_scene, from YAML text; `base_dir` resolves relative mesh paths, `origin` names the source
// in error messages.
Scene parse_scene(const std::string& yaml, const std::string& base_dir, const std::string& origin,
                  const std::vector<std::string>& overrides = {});

}  // namespace liver_sim
