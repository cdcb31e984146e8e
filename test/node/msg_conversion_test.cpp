// The node's conversions against the fields they carry: stamps to the nanosecond (the mesh's
// stamp names the pose it reflects), transforms and poses both ways, a tracker's quaternion that
// is unit to a few digits only, the refusals of a pose. No master needed.
#include <gtest/gtest.h>

#include "msg_conversion.h"

namespace liver_sim {
namespace {

TEST(MsgConversion, StampsRoundTripToTheNanosecond) {
  // Guards against: a stamp carried as seconds in a double (1.7e9 s keeps 0.24 us).
  for (const ros::Time t : {ros::Time(1700000000, 123456789), ros::Time(1, 1), ros::Time(0, 0)})
    EXPECT_EQ(to_time(to_stamp(t)), t) << t;
}

TEST(MsgConversion, TransformsAndPosesRoundTrip) {
  const Eigen::Quaterniond q = Eigen::Quaterniond(0.3, -0.5, 0.2, 0.7).normalized();
  const Eigen::Isometry3d P = Eigen::Translation3d(0.01, -0.02, 0.3) * q;
  const Eigen::Isometry3d back = to_isometry(to_transform(P));
  EXPECT_LT((back.matrix() - P.matrix()).norm(), 1e-15);
  const geometry_msgs::Pose pose = to_pose(P);
  EXPECT_EQ(pose.position.z, 0.3);
  EXPECT_NEAR(std::abs(pose.orientation.w * q.w() + pose.orientation.x * q.x() + pose.orientation.y * q.y() +
                       pose.orientation.z * q.z()),
              1.0, 1e-15);
  // A tracker's quaternion 0.05% long is a rotation still.
  geometry_msgs::Transform t = to_transform(P);
  t.rotation.w *= 1.0005;
  const Eigen::Matrix3d R = to_isometry(t).linear();
  EXPECT_LT((R * R.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-15);
}

TEST(MsgConversion, PosesAreRefusedForWhatTheyLack) {
  // Guards against: the unset orientation refused; a NaN let through.
  geometry_msgs::Pose p;
  EXPECT_EQ(pose_error(p), "");  // zeros: the identity
  EXPECT_EQ(p.orientation.w, 1.0);
  p.orientation.x = 0.5;
  EXPECT_EQ(pose_error(p), "orientation is not a unit quaternion");
  p.orientation.x = 0;
  p.position.y = std::nan("");
  EXPECT_EQ(pose_error(p), "NaN or infinite values");
}

TEST(MsgConversion, TheCapsuleRequestKeepsWhatItLeavesAtZero) {
  SetCapsule::Request req;
  req.enabled = false;
  req.thickness = 2e-4;
  const CapsuleEdit e = to_edit(req);
  EXPECT_FALSE(e.enabled);
  EXPECT_EQ(e.thickness, 2e-4);
  EXPECT_EQ(e.young_modulus, 0.0);
  SetCapsule::Response res;
  CapsuleOptions c;
  fill_response("young_modulus out of bounds", c, res);
  EXPECT_FALSE(res.success);
  EXPECT_EQ(res.message, "young_modulus out of bounds");
  fill_response("", c, res);
  EXPECT_TRUE(res.success);
  EXPECT_EQ(res.young_modulus, c.young_modulus);
}

}  // namespace
}  // namespace liver_sim
