#!/usr/bin/python3
"""Measures a running liver_sim node: CPU use at idle, and the latency from an instrument pose
message to the first mesh marker that reflects it (the marker carries the pose's stamp).

usage: scripts/measure_node.sh   (starts a master and the node on the default scene, runs this)
"""
import os
import sys
import time

import numpy as np
import rospy
from geometry_msgs.msg import PoseStamped
from visualization_msgs.msg import Marker


def cpu_seconds(pid):
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main():
    pid = int(sys.argv[1])
    rospy.init_node("liver_sim_measure")
    received = {}

    def on_mesh(m):
        t = m.header.stamp.to_nsec()
        if t not in received:
            received[t] = rospy.get_rostime()

    rospy.Subscriber("/liver_sim/mesh", Marker, on_mesh, queue_size=50)
    pub = rospy.Publisher("/instruments/tool/pose", PoseStamped, queue_size=1)
    time.sleep(3.0)  # initial solve, connections

    idle_s = 20.0
    c0, t0 = cpu_seconds(pid), time.time()
    time.sleep(idle_s)
    idle_cpu = 100.0 * (cpu_seconds(pid) - c0) / (time.time() - t0)

    sent = []
    for k in range(120):  # 5 Hz, the probe pressing 0.5-2.5 mm near a corner of the cube
        msg = PoseStamped()
        msg.header.frame_id = "liver"
        msg.header.stamp = rospy.get_rostime()
        msg.pose.position.x, msg.pose.position.y = 0.0035, 0.0035
        msg.pose.position.z = 0.015 + 0.003 - (0.0015 + 0.001 * np.sin(0.7 * k))
        msg.pose.orientation.w = 1.0
        pub.publish(msg)
        sent.append(msg.header.stamp)
        time.sleep(0.2)
    time.sleep(1.0)
    lat = np.array([(received[s.to_nsec()] - s).to_sec() * 1e3 for s in sent if s.to_nsec() in received])
    print(f"idle CPU: {idle_cpu:.2f} % of one core over {idle_s:.0f} s")
    print(f"pose -> mesh latency over {len(lat)}/{len(sent)} poses: median {np.median(lat):.1f} ms, "
          f"p99 {np.percentile(lat, 99):.1f} ms, min {lat.min():.1f} ms, max {lat.max():.1f} ms")


if __name__ == "__main__":
    main()
