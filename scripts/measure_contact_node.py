#!/usr/bin/python3
"""Measures the node as launched (launch/liver_sim.launch: the liver phantom, a 2.5 mm probe)
while a probe is driven at 30 Hz on instruments/tool/pose, pressing 2-6 mm into the sagged right lobe
and sweeping 1 cm sideways: how many of the poses reach a published mesh (each mesh carries the
stamp of the pose it reflects), the pose -> mesh latency, and the contacts and force reported.
With --clouds, camera clouds of the upper right lobe (record_demo_bag.py's, 0.5 mm noise, the
probe's surroundings hidden) are registered at 5 Hz meanwhile: the probe must keep its contacts
and its force while the clouds pull the surface.

usage: scripts/measure_contact_node.sh [SECONDS] [--clouds]   (starts a master and the node, runs this)
"""
import argparse
import math
import os
import sys
import time

import numpy as np
import rospy
from geometry_msgs.msg import PoseStamped, WrenchStamped
from liver_sim.msg import SimulationStatus
from sensor_msgs import point_cloud2
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header
from visualization_msgs.msg import Marker

RADIUS = 0.0025    # m, the launch file's probe radius
SURFACE_Z = 0.039  # m, the sagged surface of the right lobe under the probe (static equilibrium)
RATE = 30.0        # Hz, poses


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("duration", nargs="?", type=float, default=20.0, help="s")
    ap.add_argument("--clouds", action="store_true", help="register camera clouds at 5 Hz meanwhile")
    args = ap.parse_args(rospy.myargv()[1:])
    duration = args.duration
    surface, rng = None, np.random.default_rng(0)
    if args.clouds:
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        import record_demo_bag
        surface = record_demo_bag.sagged_top_surface()
    rospy.init_node("liver_sim_measure_contact")
    received, contacts, forces, registered = {}, [], [], []

    def on_mesh(m):
        t = m.header.stamp.to_nsec()
        if t not in received:
            received[t] = rospy.get_rostime()

    def on_status(s):
        contacts.append(s.active_contacts)
        registered.append(s.clouds_registered)

    def on_wrench(w):
        forces.append(w.wrench.force.z)

    rospy.Subscriber("/liver_sim/mesh", Marker, on_mesh, queue_size=100)
    rospy.Subscriber("/liver_sim/status", SimulationStatus, on_status, queue_size=100)
    rospy.Subscriber("/liver_sim/wrench", WrenchStamped, on_wrench, queue_size=100)
    pub = rospy.Publisher("/instruments/tool/pose", PoseStamped, queue_size=1)
    cloud_pub = rospy.Publisher("/points", PointCloud2, queue_size=1)
    # The node reaches its gravity equilibrium first (its status goes idle).
    idle = []
    sub = rospy.Subscriber("/liver_sim/status", SimulationStatus, lambda s: idle.append(s.state == "idle"))
    t_wait = time.time()
    while not (idle and idle[-1]) and time.time() - t_wait < 120:
        time.sleep(0.1)
    sub.unregister()
    time.sleep(0.5)
    contacts.clear(), forces.clear(), registered.clear()

    sent = []
    rate = rospy.Rate(RATE)
    t0 = time.time()
    while time.time() - t0 < duration and not rospy.is_shutdown():
        t = time.time() - t0
        msg = PoseStamped()
        msg.header.frame_id = "liver"
        msg.header.stamp = rospy.get_rostime()
        # Pressing 2-6 mm (0.4 Hz), sweeping 1 cm along x (0.2 Hz).
        depth = 0.004 + 0.002 * math.sin(2 * math.pi * 0.4 * t)
        msg.pose.position.x = -0.050 + 0.005 * math.sin(2 * math.pi * 0.2 * t)
        msg.pose.position.y = -0.020
        msg.pose.position.z = SURFACE_Z + RADIUS - depth
        msg.pose.orientation.w = 1.0
        pub.publish(msg)
        sent.append(msg.header.stamp)
        if surface is not None and len(sent) % 6 == 0:
            xy = np.array([msg.pose.position.x, msg.pose.position.y])
            cloud_pub.publish(point_cloud2.create_cloud_xyz32(Header(stamp=msg.header.stamp, frame_id="liver"),
                                                              record_demo_bag.camera_cloud(surface, rng, xy)))
        rate.sleep()
    time.sleep(1.0)
    lat = np.array([(received[s.to_nsec()] - s).to_sec() * 1e3 for s in sent if s.to_nsec() in received])
    reflected = len(lat) / duration
    print(f"poses sent: {len(sent)} in {duration:.0f} s ({len(sent) / duration:.1f}/s); reflected in a mesh: "
          f"{len(lat)} ({reflected:.1f}/s)")
    if len(lat):
        print(f"pose -> mesh latency: median {np.median(lat):.1f} ms, p95 {np.percentile(lat, 95):.1f} ms, "
              f"max {lat.max():.1f} ms")
    if contacts:
        touching = np.mean(np.array(contacts) > 0) * 100
        pushing = np.mean(np.array(forces) > 0) * 100 if forces else 0.0
        print(f"active contacts: median {np.median(contacts):.0f}, min {min(contacts)}, max {max(contacts)} "
              f"(status messages with contacts: {touching:.1f}%); force z: median {np.median(forces):.3f} N, "
              f"min {min(forces):.3f} N, max {max(forces):.3f} N (wrench messages pushing back: {pushing:.1f}%)")
    if registered:
        print(f"clouds registered: {registered[-1] - registered[0]}")


if __name__ == "__main__":
    main()
