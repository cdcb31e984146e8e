// The node's markers (src/node/mesh_marker.h) on a box, whose normals and displacements are
// known without the code under test: shading, the displacement reference, the back-to-front
// order of a translucent surface, target names and the colour legend; and the target labels on
// the package's livers as config/liver_sim.rviz's camera sees them.
#include <gtest/gtest.h>

#include <map>
#include <set>

#include <yaml-cpp/yaml.h>

#include "mesh_marker.h"
#include "liver_sim/geometry/mesh.h"
#include "liver_sim/io/scene_files.h"
#include "liver_sim/scene/scene.h"
#include "node/markers.h"
#include "regions.h"

namespace liver_sim {
namespace {

constexpr double kSide = 0.02;  // m

LiverModel box_model() {
  Scene s;
  s.fixed.push_back(box({-1, -1, -1}, {1, 1, 0}));  // the bottom face: a model must be held
  return LiverModel(make_box_mesh({kSide, kSide, kSide}, {2, 2, 2}), s);
}

// The outward unit normal of the box face a point lies on, zero on an edge or a corner.
Eigen::Vector3d face_normal(const Eigen::Vector3d& p) {
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  int faces = 0;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(p[a]) < 1e-12) n[a] = -1, ++faces;
    if (std::abs(p[a] - kSide) < 1e-12) n[a] = 1, ++faces;
  }
  return faces == 1 ? n : Eigen::Vector3d::Zero();
}

TEST(MeshMarker, VertexNormalsAreTheBoxFacesNormals) {
  const LiverModel model = box_model();
  const Eigen::MatrixX3d n = vertex_normals(model.boundary(), model.positions());
  int checked = 0;
  for (int i = 0; i < n.rows(); ++i) {
    const Eigen::Vector3d expected = face_normal(model.positions().segment<3>(3 * i));
    if (expected.isZero()) continue;
    EXPECT_TRUE(n.row(i).transpose().isApprox(expected, 1e-12)) << "node " << i << ": " << n.row(i);
    ++checked;
  }
  EXPECT_EQ(checked, 6);  // the centre of each face (2 x 2 x 2 hexahedra)
}

TEST(MeshMarker, ColourIsTheDisplacementFromTheReferenceShadedByTheLight) {
  const LiverModel model = box_model();
  const double scale = 0.005;
  Eigen::VectorXd reference = model.positions();
  for (int i = 0; i < reference.size(); i += 3) reference[i + 2] -= 2 * scale;  // every node 10 mm up from it: red
  visualization_msgs::Marker marker;
  fill_mesh_marker(model, reference, scale, 1.0, marker);
  ASSERT_EQ(marker.points.size(), 3 * static_cast<size_t>(model.boundary().rows()));
  ASSERT_EQ(marker.colors.size(), marker.points.size());
  const std_msgs::ColorRGBA moved = displacement_colour(1.0, scale);  // beyond the scale's end
  std::set<double> lights;
  for (size_t k = 0; k < marker.points.size(); ++k) {
    const Eigen::Vector3d p(marker.points[k].x, marker.points[k].y, marker.points[k].z);
    const std_msgs::ColorRGBA& c = marker.colors[k];
    EXPECT_EQ(c.a, 1.0f);
    const Eigen::Vector3d n = face_normal(p);
    if (n.isZero()) continue;
    // A face centre: lit by its face's normal; faces turned away get the ambient share only.
    const double light = 0.35 + 0.65 * std::max(0.0, n.dot(kViewerDirection));
    EXPECT_NEAR(c.r, moved.r * light, 1e-6) << "at " << p.transpose();
    EXPECT_NEAR(c.g, moved.g * light, 1e-6);
    EXPECT_NEAR(c.b, moved.b * light, 1e-6);
    lights.insert(light);
  }
  EXPECT_GE(lights.size(), 3u);  // the lit faces differ: the shape shows

  // Against itself as reference: no displacement, the ramp's start (shaded).
  fill_mesh_marker(model, model.positions(), scale, 1.0, marker);
  const std_msgs::ColorRGBA still = displacement_colour(0.0, scale);
  for (const std_msgs::ColorRGBA& c : marker.colors) EXPECT_NEAR(c.g / c.r, still.g / still.r, 1e-6);
}

TEST(MeshMarker, RampRunsFromTissueToDarkRed) {
  const std_msgs::ColorRGBA still = displacement_colour(0.0, 0.005), full = displacement_colour(0.005, 0.005);
  EXPECT_TRUE(still.r > 0.5 && still.g > 0.5 && still.b > 0.5) << "pale, so that the shading shows";
  EXPECT_TRUE(full.r > 0.5 && full.g == 0) << "red";
  const std_msgs::ColorRGBA beyond = displacement_colour(1.0, 0.005), nan = displacement_colour(NAN, 0.005);
  EXPECT_TRUE(beyond.r == full.r && beyond.g == full.g && beyond.b == full.b);
  EXPECT_TRUE(nan.r == full.r && nan.g == full.g && nan.b == full.b);
  double previous_g = 2;  // the green share falls from yellow on: warmer with more motion
  for (double u = 0.00125; u <= 0.005; u += 0.00125) {
    EXPECT_LT(displacement_colour(u, 0.005).g, previous_g);
    previous_g = displacement_colour(u, 0.005).g;
  }
}

TEST(MeshMarker, TranslucentSurfaceIsOrderedBackToFrontForTheViewer) {
  const LiverModel model = box_model();
  visualization_msgs::Marker opaque, translucent;
  fill_mesh_marker(model, model.positions(), 0.005, 1.0, opaque);
  fill_mesh_marker(model, model.positions(), 0.005, 0.3, translucent);
  ASSERT_EQ(translucent.points.size(), opaque.points.size());
  const Eigen::Vector3d view = kViewerDirection;  // config/liver_sim.rviz's viewer (ViewerIsTheRvizConfigsCamera)
  double previous = -1e9;
  std::multiset<std::vector<double>> a, b;  // the same triangles, in another order
  for (size_t t = 0; t < translucent.points.size(); t += 3) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    std::vector<double> ta, tb;
    for (int k = 0; k < 3; ++k) {
      const auto& p = translucent.points[t + k];
      const auto& q = opaque.points[t + k];
      centroid += Eigen::Vector3d(p.x, p.y, p.z) / 3;
      ta.insert(ta.end(), {p.x, p.y, p.z});
      tb.insert(tb.end(), {q.x, q.y, q.z});
      EXPECT_FLOAT_EQ(translucent.colors[t + k].a, 0.3f);
    }
    const double depth = centroid.dot(view.normalized());
    EXPECT_GE(depth, previous - 1e-12) << "triangle " << t / 3 << " is nearer the viewer than the next";
    previous = depth;
    a.insert(ta);
    b.insert(tb);
  }
  EXPECT_EQ(a, b);
}

TEST(MeshMarker, TargetNamesAndLegend) {
  std::vector<TrackedTarget> targets = {{"tumour_centre", TrackedTarget::Kind::Probe, {0.05, -0.02, 0.005}},
                                        {"portal bifurcation 3", TrackedTarget::Kind::Bifurcation, {0, 0, 0}},
                                        {"tumour_x+", TrackedTarget::Kind::Probe, {0.062, -0.02, 0.005}},
                                        {"margin", TrackedTarget::Kind::Probe, {0.01, 0.0, 0.0}}};
  const Eigen::VectorXd organ = box_model().positions().array() * 5 - 0.05;  // a 10 cm box around them
  std_msgs::Header header;
  header.frame_id = "liver";
  visualization_msgs::MarkerArray markers;
  append_target_names(targets, organ, header, markers);
  std::map<int, std::string> names;  // target index -> label
  int leaders = 0;
  for (const visualization_msgs::Marker& m : markers.markers) {
    EXPECT_EQ(m.header.frame_id, "liver");
    if (m.ns == "target_leaders") {
      ++leaders;
      EXPECT_EQ(m.points.size(), 2 * names.size());
      continue;
    }
    EXPECT_EQ(m.ns, "target_names");
    EXPECT_EQ(m.type, visualization_msgs::Marker::TEXT_VIEW_FACING);
    EXPECT_GE(m.scale.z, 0.005) << "text of 5 mm or more: readable beside a 20 cm liver";
    names[m.id] = m.text;
  }
  EXPECT_EQ(leaders, 1);
  // The tumour's centre speaks for its margin point; the other probe and the bifurcation speak for themselves.
  EXPECT_EQ(names, (std::map<int, std::string>{{0, "tumour"}, {1, "P3"}, {3, "margin"}}));

  markers.markers.clear();
  const Eigen::AlignedBox3d box(Eigen::Vector3d(-0.1, -0.05, -0.03), Eigen::Vector3d(0.1, 0.05, 0.06));
  append_colour_legend(box, 0.008, header, markers);
  std::vector<const visualization_msgs::Marker*> cubes;
  std::vector<std::string> texts;
  for (const visualization_msgs::Marker& m : markers.markers) {
    EXPECT_EQ(m.ns, "legend");
    if (m.type == visualization_msgs::Marker::CUBE) cubes.push_back(&m);
    if (m.type == visualization_msgs::Marker::TEXT_VIEW_FACING) texts.push_back(m.text);
    EXPECT_LT(m.pose.position.z, box.min().z());  // under the model and in front of it, not in it
    EXPECT_LT(m.pose.position.y, box.min().y());
  }
  ASSERT_GE(cubes.size(), 2u);
  std::set<int> ids;
  for (const visualization_msgs::Marker& m : markers.markers) ids.insert(m.id);
  EXPECT_EQ(ids.size(), markers.markers.size());
  // Left: no displacement; right: the scale's end; rising in between.
  const std_msgs::ColorRGBA still = displacement_colour(0.0, 0.008), full = displacement_colour(0.008, 0.008);
  EXPECT_TRUE(cubes.front()->color.r == still.r && cubes.front()->color.g == still.g && cubes.front()->color.b == still.b);
  EXPECT_TRUE(cubes.back()->color.r == full.r && cubes.back()->color.g == full.g && cubes.back()->color.b == full.b);
  for (size_t k = 1; k < cubes.size(); ++k) EXPECT_GT(cubes[k]->pose.position.x, cubes[k - 1]->pose.position.x);
  EXPECT_NE(std::find(texts.begin(), texts.end(), "0"), texts.end());
  EXPECT_NE(std::find(texts.begin(), texts.end(), "4"), texts.end());
  EXPECT_NE(std::find(texts.begin(), texts.end(), ">= 8"), texts.end());
  EXPECT_NE(std::find(texts.begin(), texts.end(), "displacement (mm)"), texts.end());
}

// The camera config/liver_sim.rviz opens with, read from the file: rviz's orbit view puts the eye
// `Distance` from the focal point along (cos yaw cos pitch, sin yaw cos pitch, sin pitch), looking
// at it, z up. A point's place on the screen is its perspective projection (in focal lengths).
struct RvizView {
  Eigen::Vector3d eye, forward, right, up;
  RvizView() {
    const YAML::Node v =
        YAML::LoadFile(std::string(LIVER_SIM_SOURCE_DIR) + "/config/liver_sim.rviz")["Visualization Manager"]["Views"]["Current"];
    const double yaw = v["Yaw"].as<double>(), pitch = v["Pitch"].as<double>();
    const Eigen::Vector3d focal(v["Focal Point"]["X"].as<double>(), v["Focal Point"]["Y"].as<double>(),
                                v["Focal Point"]["Z"].as<double>());
    eye = focal + v["Distance"].as<double>() *
                      Eigen::Vector3d(std::cos(yaw) * std::cos(pitch), std::sin(yaw) * std::cos(pitch), std::sin(pitch));
    forward = (focal - eye).normalized();
    right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    up = right.cross(forward);
  }
  Eigen::Vector2d project(const Eigen::Vector3d& p) const {
    const Eigen::Vector3d d = p - eye;
    return Eigen::Vector2d(d.dot(right), d.dot(up)) / d.dot(forward);
  }
  // A TEXT_VIEW_FACING marker's text on the screen: its box, at most 0.6 of its height wide per
  // character (rviz's font, measured on its screenshots: 0.5-0.57) and its height high.
  Eigen::AlignedBox2d text_box(const visualization_msgs::Marker& m) const {
    const Eigen::Vector3d at(m.pose.position.x, m.pose.position.y, m.pose.position.z);
    const double per_metre = 1.0 / (at - eye).dot(forward);
    const Eigen::Vector2d half(0.3 * m.scale.z * m.text.size() * per_metre, 0.5 * m.scale.z * per_metre);
    return Eigen::AlignedBox2d(project(at) - half, project(at) + half);
  }
};

// The node's view is the rviz config's: the surface's light and the labels' layout come from its camera.
TEST(MeshMarker, ViewerIsTheRvizConfigsCamera) {
  const RvizView view;
  EXPECT_LT((-view.forward - kViewerDirection).norm(), 1e-12) << -view.forward.transpose();
}

// The OR demo's liver (SOFA's liver2) and the phantom at their equilibrium, as the node shows
// them in config/liver_sim.rviz's view: every text (the targets' labels, the legend's, the axes'
// L P S) is in the view, no two overlap on the screen, no label covers the organ, and a leader line joins each
// label's organ-side end to its target. Checked to fail with the labels at their anchors'
// heights without the column's spacing (line 0), and with the columns' inner ends 2 cm inside
// the silhouette's extremes instead of a height outside them.
class LabelsInTheRvizView : public ::testing::TestWithParam<const char*> {};

TEST_P(LabelsInTheRvizView, ApartOffTheOrganAndLedToTheirTargets) {
  const Scene scene = load_scene(std::string(LIVER_SIM_SOURCE_DIR) + "/config/scenes/" + GetParam());
  LiverModel model(load_scene_mesh(scene), scene);
  ASSERT_TRUE(model.step().converged());
  const std::vector<TrackedTarget> targets = tracked_targets(model);
  ASSERT_GE(targets.size(), 7u);
  const Eigen::MatrixX3d& rest = model.mesh().V;
  const Eigen::AlignedBox3d box(rest.colwise().minCoeff().transpose(), rest.colwise().maxCoeff().transpose());
  visualization_msgs::MarkerArray markers;
  append_annotations(targets, model.positions(), box, 0.005, std_msgs::Header(), markers);

  const RvizView view;
  std::vector<const visualization_msgs::Marker*> texts, labels;
  const visualization_msgs::Marker* leaders = nullptr;
  for (const visualization_msgs::Marker& m : markers.markers) {
    if (m.type == visualization_msgs::Marker::TEXT_VIEW_FACING) texts.push_back(&m);
    if (m.ns == "target_names") labels.push_back(&m);
    if (m.ns == "target_leaders") leaders = &m;
  }
  ASSERT_NE(leaders, nullptr);
  ASSERT_EQ(leaders->points.size(), 2 * labels.size());
  ASSERT_GE(labels.size(), 4u);
  // rviz's camera (Ogre's default) sees 45 degrees high, and 1.2 times as wide in the config's
  // window (its render panel, beside the Displays panel, is 900 x 710 pixels in a screenshot).
  const double half_view = std::tan(M_PI / 8);
  const Eigen::AlignedBox2d window(Eigen::Vector2d(-1.2 * half_view, -half_view), Eigen::Vector2d(1.2 * half_view, half_view));
  for (size_t i = 0; i < texts.size(); ++i)
    EXPECT_TRUE(window.contains(view.text_box(*texts[i]))) << "'" << texts[i]->text << "' is out of the view at "
                                                            << view.project(position(*texts[i])).transpose();
  for (size_t i = 0; i < texts.size(); ++i)
    for (size_t j = 0; j < i; ++j)
      EXPECT_FALSE(view.text_box(*texts[i]).intersects(view.text_box(*texts[j])))
          << "'" << texts[i]->text << "' overlaps '" << texts[j]->text << "' on the screen";

  // The organ on the screen: its boundary triangles' corners, edge midpoints and centroids.
  const Eigen::MatrixX3i& F = model.boundary();
  const Eigen::VectorXd& x = model.positions();
  std::vector<Eigen::Vector2d> organ;
  for (int f = 0; f < F.rows(); ++f)
    for (const Eigen::Vector3d& w : {Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0.5, 0.5, 0), Eigen::Vector3d(1 / 3.0, 1 / 3.0, 1 / 3.0),
                                     Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(0, 0.5, 0.5), Eigen::Vector3d(0, 0, 1),
                                     Eigen::Vector3d(0.5, 0, 0.5)})
      organ.push_back(view.project(w[0] * x.segment<3>(3 * F(f, 0)) + w[1] * x.segment<3>(3 * F(f, 1)) +
                                   w[2] * x.segment<3>(3 * F(f, 2))));
  for (size_t k = 0; k < labels.size(); ++k) {
    const visualization_msgs::Marker& label = *labels[k];
    const Eigen::AlignedBox2d on_screen = view.text_box(label);
    for (const Eigen::Vector2d& p : organ) EXPECT_FALSE(on_screen.contains(p)) << "'" << label.text << "' covers the organ";
    const auto& a = leaders->points[2 * k];
    const auto& b = leaders->points[2 * k + 1];
    EXPECT_LT((Eigen::Vector3d(a.x, a.y, a.z) - targets.at(label.id).position).norm(), 1e-12) << label.text;
    // The line's other end on the label's box, at its middle height (within a character's width).
    const Eigen::Vector2d end = view.project(Eigen::Vector3d(b.x, b.y, b.z));
    EXPECT_LT(on_screen.exteriorDistance(end), 0.6 * on_screen.sizes().y()) << label.text;
    EXPECT_NEAR(end.y(), on_screen.center().y(), 1e-9) << label.text;
  }
}

INSTANTIATE_TEST_SUITE_P(Scenes, LabelsInTheRvizView, ::testing::Values("sofa_liver_or.yaml", "liver_phantom.yaml"));

// Labels of targets crowded together (a cluster of bifurcations 2 mm apart in a 4 cm organ) end
// apart on the screen of config/liver_sim.rviz and outside the organ's silhouette. Checked to
// fail without the column's spacing (line 0) and with the columns a height inside the silhouette.
TEST(MeshMarker, CrowdedLabelsDoNotOverlap) {
  const double h = 0.006;
  std::vector<Eigen::Vector3d> anchors;
  std::vector<std::string> texts;
  for (int i = 0; i < 12; ++i) {
    anchors.emplace_back(0.002 * (i % 4), 0.001 * i, 0.002 * (i / 4));
    texts.push_back(i == 5 ? "tumour" : "P" + std::to_string(i));
  }
  const Eigen::VectorXd organ = box_model().positions().array() * 2 - 0.02;  // a 4 cm box around them
  const LabelLayout layout = label_positions(anchors, texts, h, organ);
  ASSERT_EQ(layout.at.size(), anchors.size());
  const RvizView view;
  auto box = [&](size_t i) {
    visualization_msgs::Marker m;
    m.pose.position.x = layout.at[i].x();
    m.pose.position.y = layout.at[i].y();
    m.pose.position.z = layout.at[i].z();
    m.scale.z = h;
    m.text = texts[i];
    return view.text_box(m);
  };
  Eigen::AlignedBox2d silhouette;
  for (int i = 0; i < organ.size(); i += 3) silhouette.extend(view.project(organ.segment<3>(i)));
  for (size_t i = 0; i < anchors.size(); ++i) {
    EXPECT_FALSE(box(i).intersects(silhouette)) << texts[i] << " lies on the organ";
    for (size_t j = 0; j < i; ++j) EXPECT_FALSE(box(i).intersects(box(j))) << texts[i] << " overlaps " << texts[j];
  }
}

// The patient's orientation: arrows along +x, +y, +z labelled L, P, S, outside the model's box.
TEST(MeshMarker, OrientationAxesNameThePatientsSides) {
  const Eigen::AlignedBox3d box(Eigen::Vector3d(-0.1, -0.05, -0.03), Eigen::Vector3d(0.1, 0.05, 0.06));
  std_msgs::Header header;
  visualization_msgs::MarkerArray markers;
  append_orientation_axes(box, header, markers);
  std::map<std::string, Eigen::Vector3d> label_direction;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  for (const visualization_msgs::Marker& m : markers.markers) {
    EXPECT_EQ(m.ns, "orientation");
    if (m.type == visualization_msgs::Marker::ARROW) {
      ASSERT_EQ(m.points.size(), 2u);
      origin = Eigen::Vector3d(m.points[0].x, m.points[0].y, m.points[0].z);
      EXPECT_FALSE(box.contains(origin));
    }
  }
  for (const visualization_msgs::Marker& m : markers.markers)
    if (m.type == visualization_msgs::Marker::TEXT_VIEW_FACING)
      label_direction[m.text] = (Eigen::Vector3d(m.pose.position.x, m.pose.position.y, m.pose.position.z) - origin).normalized();
  ASSERT_EQ(label_direction.size(), 3u);
  EXPECT_GT(label_direction["L"].x(), 0.99);  // LPS: +x the patient's left
  EXPECT_GT(label_direction["P"].y(), 0.99);
  EXPECT_GT(label_direction["S"].z(), 0.99);
}

}  // namespace
}  // namespace liver_sim
