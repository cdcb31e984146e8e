// Scene files: parsing, defaults, overrides, and clear errors naming the key; regions.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "liver_sim/scene/scene.h"

namespace liver_sim {
namespace {

const char* kFull = R"(
mesh: {file: meshes/liver.msh, scale: 0.01}
parenchyma: {young_modulus: 30000, poisson_ratio: 0.49, density: 1050, rotation: geometric}
capsule: {enabled: true, young_modulus: 3.0e6, thickness: 93e-6, poisson_ratio: 0.3,
          region: {sphere: {center: [0, 0, 0], radius: 0.05}}}
fixed:
  - box: {min: [-1, -1, -1], max: [1, 1, 0]}
  - disc: {center: [0.0075, 0.0075, 0.015], normal: [0, 0, 2], radius: 0.0065, inner_radius: 0.005, depth: 0.0001}
loads:
  - {type: pressure, value: -3000, region: {disc: {center: [0, 0, 1], normal: [0, 0, 1], radius: 0.005}}}
  - {type: gravity, acceleration: [0, 0, -9.81]}
  - {type: force, total: [0, 0.5, 0], region: {box: {min: [0, 0, 0], max: [1, 1, 1]}}}
solver: {mode: dynamic, predictor: constant_acceleration, dt: 0.001, steps: 20, max_iterations: 5, tolerance: 1e-7, line_search: false,
         rayleigh_mass: 0.5, rayleigh_stiffness: 0.01, time_budget: 0.02, capped_residual: 0.01}
probes: [{name: centre, point: [0.0075, 0.0075, 0.015]}]
)";

const char* kMinimal = "mesh: {box: {size: [0.01, 0.02, 0.03], divisions: [1, 2, 3]}}\n";

std::string error_of(const std::string& yaml, const std::vector<std::string>& overrides = {}) {
  try {
    parse_scene(yaml, "/base", "scene.yaml", overrides);
  } catch (const SceneError& e) {
    return e.what();
  }
  return "";
}

#define EXPECT_ERROR(yaml, text)                                  \
  do {                                                            \
    const std::string message_ = error_of(yaml);                  \
    EXPECT_NE(message_.find(text), std::string::npos) << message_; \
    EXPECT_EQ(message_.rfind("scene.yaml: ", 0), 0u) << message_;  \
  } while (0)

TEST(Scene, ParsesEverySection) {
  const Scene s = parse_scene(kFull, "/base", "scene.yaml");
  EXPECT_EQ(s.mesh.file, "/base/meshes/liver.msh");
  EXPECT_EQ(s.mesh.scale, 0.01);
  EXPECT_EQ(s.parenchyma.young_modulus, 30000);
  EXPECT_EQ(s.parenchyma.poisson_ratio, 0.49);
  EXPECT_EQ(s.parenchyma.density, 1050);
  EXPECT_EQ(s.parenchyma.rotation, RotationMethod::Geometric);
  EXPECT_TRUE(s.capsule.enabled);
  EXPECT_EQ(s.capsule.thickness, 93e-6);
  ASSERT_TRUE(s.capsule.region.has_value());
  EXPECT_EQ(s.capsule.region->kind, Region::Kind::Sphere);
  ASSERT_EQ(s.fixed.size(), 2u);
  EXPECT_EQ(s.fixed[1].kind, Region::Kind::Disc);
  EXPECT_EQ(s.fixed[1].inner_radius, 0.005);
  EXPECT_EQ(s.fixed[1].depth, 0.0001);
  ASSERT_EQ(s.loads.size(), 3u);
  EXPECT_EQ(s.loads[0].kind, LoadOptions::Kind::Pressure);
  EXPECT_EQ(s.loads[0].pressure, -3000);
  EXPECT_EQ(s.loads[1].kind, LoadOptions::Kind::Gravity);
  EXPECT_EQ(s.loads[1].vector.z(), -9.81);
  EXPECT_EQ(s.loads[2].kind, LoadOptions::Kind::Force);
  EXPECT_EQ(s.loads[2].vector.y(), 0.5);
  EXPECT_EQ(s.solver.mode, SolverOptions::Mode::Dynamic);
  EXPECT_EQ(s.solver.steps, 20);
  EXPECT_FALSE(s.solver.line_search);
  EXPECT_EQ(s.solver.rayleigh_stiffness, 0.01);
  EXPECT_EQ(s.solver.time_budget, 0.02);
  EXPECT_EQ(s.solver.capped_residual, 0.01);
  EXPECT_EQ(s.solver.predictor, SolverOptions::Predictor::ConstantAcceleration);
  ASSERT_EQ(s.probes.size(), 1u);
  EXPECT_EQ(s.probes[0].point.z(), 0.015);
}

TEST(Scene, DefaultsWhenSectionsAreMissing) {
  const Scene s = parse_scene(kMinimal, "/base", "scene.yaml");
  EXPECT_TRUE(s.mesh.file.empty());
  EXPECT_EQ(s.mesh.box_divisions, Eigen::Vector3i(1, 2, 3));
  EXPECT_EQ(s.parenchyma.young_modulus, ParenchymaOptions{}.young_modulus);
  EXPECT_EQ(s.parenchyma.rotation, RotationMethod::Polar);
  EXPECT_FALSE(s.capsule.enabled);
  EXPECT_TRUE(s.fixed.empty() && s.loads.empty() && s.probes.empty());
  EXPECT_EQ(s.solver.mode, SolverOptions::Mode::Static);
}

TEST(Scene, OverridesScalarsCreatingMissingKeysAndIndexingLists) {
  const Scene s = parse_scene(kFull, "/base", "scene.yaml",
                              {"capsule.enabled=false", "loads.0.value=-5000", "solver.mode=static", "solver.predictor=none"});
  EXPECT_FALSE(s.capsule.enabled);
  EXPECT_EQ(s.solver.predictor, SolverOptions::Predictor::None);
  EXPECT_EQ(s.loads[0].pressure, -5000);
  EXPECT_EQ(s.solver.mode, SolverOptions::Mode::Static);
  const Scene m = parse_scene(kMinimal, "/base", "scene.yaml", {"capsule.enabled=true", "capsule.thickness=1e-5"});
  EXPECT_TRUE(m.capsule.enabled);
  EXPECT_EQ(m.capsule.thickness, 1e-5);
}

TEST(Scene, BadOverridesNameTheOverride) {
  EXPECT_NE(error_of(kFull, {"capsule.enabled"}).find("--set capsule.enabled"), std::string::npos);
  EXPECT_NE(error_of(kFull, {"solver.dt.x=1"}).find("through a scalar"), std::string::npos);
  EXPECT_NE(error_of(kFull, {"loads.7.value=1"}).find("out of range"), std::string::npos);
  EXPECT_NE(error_of(kFull, {"loads.x.value=1"}).find("not a list index"), std::string::npos);
  EXPECT_NE(error_of(kFull, {"capsule=1"}).find("only scalars"), std::string::npos);
  EXPECT_NE(error_of(kFull, {"capsule.thicknes=1"}).find("unknown key 'capsule.thicknes'"), std::string::npos);
}

TEST(Scene, UnknownKeysAndWrongTypesNameTheKey) {
  EXPECT_ERROR(std::string(kMinimal) + "solvr: {}\n", "unknown key 'solvr'");
  EXPECT_ERROR(std::string(kMinimal) + "capsule: {thicknes: 1}\n", "unknown key 'capsule.thicknes'");
  EXPECT_ERROR(std::string(kMinimal) + "loads: [{type: force, total: [0, 0, 1], region: {box: {min: [0,0,0], maks: [1,1,1]}}}]\n",
               "unknown key 'loads.0.region.box.maks'");
  EXPECT_ERROR(std::string(kMinimal) + "parenchyma: {young_modulus: soft}\n", "parenchyma.young_modulus: expected a number");
  EXPECT_ERROR(std::string(kMinimal) + "parenchyma: {young_modulus: .nan}\n", "must be finite");
  EXPECT_ERROR(std::string(kMinimal) + "parenchyma: {rotation: qr}\n", "parenchyma.rotation: expected");
  EXPECT_ERROR(std::string(kMinimal) + "solver: {mode: quasi}\n", "solver.mode");
  EXPECT_ERROR(std::string(kMinimal) + "solver: {predictor: cubic}\n", "solver.predictor");
  EXPECT_ERROR(std::string(kMinimal) + "probes: [{name: a, point: [0, 0]}]\n", "probes.0.point: expected a list of 3");
  EXPECT_ERROR(std::string(kMinimal) + "probes: [{name: a, point: [0, 0, 0]}, {name: a, point: [0, 0, 0]}]\n", "unique");
  EXPECT_ERROR(std::string(kMinimal) + "loads: [{type: magnetic}]\n", "loads.0.type");
  EXPECT_ERROR(std::string(kMinimal) + "loads: [{type: force, total: [0, 0, 1]}]\n", "loads.0.region: missing");
  EXPECT_ERROR("mesh: {box: {size: [1, 1, 1], divisions: [2, 2.5, 2]}}\n", "mesh.box.divisions.1: expected an integer");
  EXPECT_ERROR("mesh: {file: a.msh, box: {size: [1, 1, 1], divisions: [1, 1, 1]}}\n", "exactly one of file, box");
  EXPECT_ERROR("parenchyma: {}\n", "mesh: missing");
  EXPECT_ERROR(std::string(kMinimal) + "fixed: [{box: {min: [0,0,0], max: [1,1,1]}, sphere: {center: [0,0,0], radius: 1}}]\n",
               "fixed.0: expected exactly one of box, sphere, disc");
  EXPECT_ERROR("mesh: [1, 2\n", "YAML syntax");
  EXPECT_ERROR("mesh: " + std::string(10000, '[') + "\n", "nested deeper than 32 levels");
}

TEST(Scene, InvalidValuesAreRefusedNamingTheField) {
  const std::string m = kMinimal;
  EXPECT_ERROR(m + "parenchyma: {young_modulus: 0}\n", "parenchyma.young_modulus");
  EXPECT_ERROR(m + "parenchyma: {poisson_ratio: 0.5}\n", "parenchyma.poisson_ratio");
  EXPECT_ERROR(m + "parenchyma: {poisson_ratio: -1}\n", "parenchyma.poisson_ratio");
  EXPECT_ERROR(m + "capsule: {thickness: 0}\n", "capsule.thickness");
  EXPECT_ERROR(m + "capsule: {young_modulus: -8e6}\n", "capsule.young_modulus");
  EXPECT_ERROR(m + "solver: {dt: 0}\n", "solver.dt");
  EXPECT_ERROR(m + "solver: {steps: 0}\n", "solver.steps");
  EXPECT_ERROR(m + "fixed: [{disc: {center: [0,0,0], normal: [0,0,1], radius: 1, inner_radius: 1}}]\n", "inner_radius");
  EXPECT_ERROR(m + "fixed: [{disc: {center: [0,0,0], normal: [0,0,0], radius: 1}}]\n", "normal");
  EXPECT_ERROR(m + "fixed: [{box: {min: [0,0,1], max: [1,1,1]}}]\n", "min must be below max");
  EXPECT_ERROR(m + "fixed: [{sphere: {center: [0,0,0], radius: -1}}]\n", "sphere.radius");
  EXPECT_ERROR("mesh: {box: {size: [1, 0, 1], divisions: [1, 1, 1]}}\n", "mesh.box.size");
  EXPECT_ERROR("mesh: {file: a.msh, scale: 0}\n", "mesh.scale");
}

TEST(Scene, LoadsFilesResolvingRelativeMeshPaths) {
  const auto dir = std::filesystem::temp_directory_path() / "liver_sim_test_scene";
  std::filesystem::create_directories(dir);
  const auto path = dir / "s.yaml";
  std::ofstream(path) << kFull;
  const Scene s = load_scene(path.string());
  EXPECT_EQ(s.mesh.file, (dir / "meshes/liver.msh").string());
  try {
    load_scene((dir / "missing.yaml").string());
    FAIL();
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.yaml: cannot open"), std::string::npos);
  }
}

TEST(Scene, InstrumentsTrajectoriesAndContact) {
  const std::string yaml = std::string(kMinimal) + R"(
instruments:
  - {name: tip, type: probe, radius: 0.004, pose: {position: [0, 0, 0.05]}}
  - name: jaws
    type: grasper
    radius: 0.003
    trajectory:
      - {t: 0, position: [0, 0, 0.03], closed: true}
      - {t: 1, position: [0, 0, 0.04], orientation: [0, 0, 0.7071068, 0.7071068]}
  - {name: tube, type: tube, inner_radius: 0.005, outer_radius: 0.0065, length: 0.02, suction: 3000,
     pose: {position: [0, 0, 0.03], orientation: [1, 0, 0, 0]}}
contact: {friction: 0.3, alarm_distance: 0.001, tolerance: 1e-8, max_iterations: 200}
)";
  const Scene s = parse_scene(yaml, "/base", "scene.yaml");
  ASSERT_EQ(s.instruments.size(), 3u);
  EXPECT_EQ(s.instruments[0].type, InstrumentOptions::Type::Probe);
  EXPECT_EQ(s.instruments[0].radius, 0.004);
  EXPECT_EQ(s.instruments[0].position, Eigen::Vector3d(0, 0, 0.05));
  ASSERT_EQ(s.instruments[1].trajectory.size(), 2u);
  EXPECT_TRUE(*s.instruments[1].trajectory[0].closed);
  EXPECT_FALSE(s.instruments[1].trajectory[1].closed.has_value());
  EXPECT_NEAR(s.instruments[1].trajectory[1].orientation.w(), std::sqrt(0.5), 1e-7);
  EXPECT_EQ(s.instruments[2].suction, 3000);
  EXPECT_EQ(s.instruments[2].orientation.x(), 1.0);
  EXPECT_EQ(s.contact.friction, 0.3);
  EXPECT_EQ(s.contact.alarm_distance, 0.001);
  EXPECT_EQ(s.contact.max_iterations, 200);
  EXPECT_EQ(parse_scene(yaml, "/base", "scene.yaml", {"instruments.2.suction=1000"}).instruments[2].suction, 1000);

  auto instrument_error = [](const std::string& item) {
    return error_of(std::string(kMinimal) + "instruments:\n  - " + item + "\n");
  };
  EXPECT_NE(instrument_error("{name: a, type: probe, radius: 0, pose: {position: [0, 0, 0]}}").find("instruments.a.radius"), std::string::npos);
  EXPECT_NE(instrument_error("{name: a, type: probe, radius: -1, pose: {position: [0, 0, 0]}}").find("radius"), std::string::npos);
  EXPECT_NE(instrument_error("{name: a, type: laser, pose: {position: [0, 0, 0]}}").find("instruments.0.type"), std::string::npos);
  EXPECT_NE(instrument_error("{name: a, type: probe}").find("needs a pose or a trajectory"), std::string::npos);
  EXPECT_NE(instrument_error("{name: a, type: probe, pose: {position: [0, 0, .nan]}}").find("must be finite"), std::string::npos);
  EXPECT_NE(instrument_error("{name: a, type: probe, pose: {position: [0, 0, 0], orientation: [0, 0, 0, 0]}}").find("non-zero"), std::string::npos);
  EXPECT_NE(instrument_error("{name: a, type: probe, inner_radius: 1, pose: {position: [0, 0, 0]}}").find("unknown key 'instruments.0.inner_radius'"), std::string::npos);
  EXPECT_NE(instrument_error("{name: a, type: probe, trajectory: [{t: 1, position: [0, 0, 0]}, {t: 1, position: [0, 0, 1]}]}").find("increase"), std::string::npos);
  EXPECT_NE(instrument_error("{name: a, type: probe, trajectory: [{t: 0, position: [0, 0, 0], closed: true}]}").find("only a grasper"), std::string::npos);
  EXPECT_NE(instrument_error("{name: a, type: tube, inner_radius: 0.006, outer_radius: 0.005, pose: {position: [0, 0, 0]}}").find("outer_radius"), std::string::npos);
  EXPECT_NE(error_of(std::string(kMinimal) + "contact: {friction: -0.1}\n").find("contact.friction"), std::string::npos);
  EXPECT_NE(error_of(std::string(kMinimal) + "contact: {tolerance: 0}\n").find("contact.tolerance"), std::string::npos);
}

TEST(Region, ContainsEachKindFacesIncluded) {
  Region box;
  box.kind = Region::Kind::Box;
  box.min = {0, 0, 0};
  box.max = {0.015, 0.015, 0.0};
  EXPECT_TRUE(box.contains({0.015, 0.0, 0.0}));
  EXPECT_FALSE(box.contains({0.01, 0.01, 1e-6}));

  Region sphere;
  sphere.kind = Region::Kind::Sphere;
  sphere.radius = 1.0;
  EXPECT_TRUE(sphere.contains({0, 1, 0}));
  EXPECT_FALSE(sphere.contains({0, 1.001, 0}));

  Region disc;
  disc.kind = Region::Kind::Disc;
  disc.center = {0, 0, 1};
  disc.normal = {0, 0, 3};  // normalised inside
  disc.radius = 0.0065;
  disc.inner_radius = 0.005;
  disc.depth = 0.0001;
  EXPECT_TRUE(disc.contains({0.006, 0, 1}));
  EXPECT_TRUE(disc.contains({0.005, 0, 1.00005}));
  EXPECT_FALSE(disc.contains({0.004, 0, 1}));    // inside the inner radius
  EXPECT_FALSE(disc.contains({0.007, 0, 1}));    // beyond the radius
  EXPECT_FALSE(disc.contains({0.006, 0, 1.001}));  // too far from the plane
  disc.depth = -1;  // default: 5% of the radius
  EXPECT_TRUE(disc.contains({0.006, 0, 1 + 0.04 * 0.0065}));
  EXPECT_FALSE(disc.contains({0.006, 0, 1 + 0.06 * 0.0065}));
}

}  // namespace
}  // namespace liver_sim
