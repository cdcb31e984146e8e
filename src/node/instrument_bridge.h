// The instruments as an OR's tracking system drives them over ROS: instrument_command declares,
// changes and removes them (TrackingSession, instrument_slots.h, keeps the bookkeeping); each is
// posed from its own topic (instruments/<name>/pose, in any tf frame) or from a tf frame looked
// up at the start of each frame; each has its own wrench topic, and a topic-driven one its tip
// frame in tf. Callbacks validate, convert and submit; the simulation thread polls the frames
// and publishes.
#pragma once

#include <geometry_msgs/PoseStamped.h>
#include <ros/ros.h>
#include <std_msgs/Header.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>

#include <map>
#include <mutex>
#include <string>

#include "liver_sim/InstrumentCommand.h"
#include "liver_sim/session/tracking_session.h"

namespace liver_sim {

class InstrumentBridge {
 public:
  // Subscribes instrument_command and the pose topics of the session's instruments.
  InstrumentBridge(ros::NodeHandle& nh, ros::NodeHandle& pnh, tf2_ros::Buffer& tf, TrackingSession& session,
                   const std::string& frame_id, double tf_timeout);

  // Simulation thread, before the session's frame: the tf-driven instruments' transforms.
  void poll_frames();
  // Simulation thread, after it: the topics of removed instruments closed; the markers redrawn
  // at the next publish() when the model's instruments changed.
  void after_frame(bool redrawn);
  // Each instrument's wrench (its frame, at its tip), the total (model frame, about its origin),
  // the tip frames of topic-driven instruments, and the instrument markers when they changed.
  void publish(const std_msgs::Header& header);

 private:
  struct Topics {
    ros::Subscriber pose_sub;
    ros::Publisher wrench_pub;
    Eigen::Isometry3d drawn = Eigen::Isometry3d::Identity();  // the model's pose last published
  };
  void on_command(const InstrumentCommand::ConstPtr& msg);
  void on_pose(const std::string& name, const geometry_msgs::PoseStamped::ConstPtr& msg);
  void open(const std::string& name);  // the instrument's topics, unless open (mutex held)

  ros::NodeHandle nh_, pnh_;
  tf2_ros::Buffer& tf_;
  TrackingSession& session_;
  std::string frame_id_;
  double tf_timeout_;  // s: how long a pose waits for its transform
  tf2_ros::TransformBroadcaster tip_broadcaster_;
  ros::Subscriber command_sub_;
  ros::Publisher wrench_pub_, marker_pub_;
  std::mutex mutex_;  // guards topics_
  std::map<std::string, Topics> topics_;
  bool markers_due_ = true;  // simulation thread
  // The stamp each tip frame was last broadcast with (simulation thread): a frame goes out again
  // only with another, as tf takes a transform once per stamp (a bag's clock that stands
  // still would otherwise repeat it, and every listener warn TF_REPEATED_DATA).
  std::map<std::string, ros::Time> tip_stamps_;
};

}  // namespace liver_sim
