#!/usr/bin/python3
"""Measures a running liver_sim node the way an OR team drives it: a probe posed at 30 Hz above the
tumour, pressing 2-6 mm into the liver while it sweeps 1 cm to and fro, optionally with a depth
camera's clouds, and reports meshes per second while the probe moves and the pose-to-mesh latency
(a mesh marker carries the stamp of the newest input it reflects; a pose's latency is the time from
its stamp to the first mesh that shows it or a later pose). A mesh's arrival is taken from its raw
bytes: decoding a marker of the phantom's surface in Python takes longer than the node's frame, and
would be measured as latency.

usage: scripts/measure_or.py [--duration S] [--clouds HZ] [--json FILE]
       (with ROS_MASTER_URI of the node's master; scripts/measure_or.sh starts a node and runs it)
"""
import argparse
import json
import math
import os
import struct
import sys
import time

import numpy as np
import rospy
from sensor_msgs import point_cloud2
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header

from liver_sim.msg import SimulationStatus

sys.path.insert(0, os.path.dirname(os.path.realpath(__file__)))
from or_demo import FRAME, NODE, Camera, Instrument, Session, surface_height  # noqa: E402

POSE_RATE = 30.0     # Hz
PRESS = (0.002, 0.006)  # m below the surface: the press goes between these
SWEEP = 0.010        # m along x
PERIOD = 2.0         # s of one press-and-sweep cycle
RADIUS = 0.0025      # m, the probe's


def input_latencies(sent, meshes):
    """Per input stamp (ns, sorted), the time (s) from it to the first mesh marker (arrival s, stamp
    ns) whose stamp is it or a later input's; inputs never shown are left out."""
    if not meshes:
        return np.array([])
    arrival = np.array([a for a, _ in meshes])
    newest = np.maximum.accumulate(np.array([s for _, s in meshes], dtype=np.int64))
    sent = np.array(sent, dtype=np.int64)
    first = np.searchsorted(newest, sent)  # the first mesh, in arrival order, showing the input
    shown = first < len(newest)
    return arrival[first[shown]] - sent[shown] * 1e-9


def raw_stamp(message):
    """The header stamp (ns) of a serialised message that starts with a std_msgs/Header."""
    _, secs, nsecs = struct.unpack_from("<III", message._buff)
    return secs * 1_000_000_000 + nsecs


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=20.0, help="seconds the probe moves (default 20)")
    ap.add_argument("--clouds", type=float, default=0.0, help="camera clouds per second beside the poses (0: none)")
    ap.add_argument("--json", help="also write the results to this file")
    args = ap.parse_args(rospy.myargv()[1:])
    rospy.init_node("liver_sim_measure_or", anonymous=True)
    rng = np.random.default_rng(1)
    session = Session()
    meshes = []  # (arrival time (s), stamp (ns)) of every mesh marker
    session.wait_for_equilibrium(120, "measure_or")
    with session.lock:
        tumour = session.targets[0].copy()
    triangles = session.triangles()
    session.mesh_subscriber.unregister()  # the surface is known: no more markers decoded here
    rospy.Subscriber("/liver_sim/mesh", rospy.AnyMsg, lambda m: meshes.append((time.time(), raw_stamp(m))),
                     queue_size=50)
    surface = surface_height(triangles, tumour[:2])
    camera = Camera(triangles, rng) if args.clouds > 0 else None
    cloud_pub = rospy.Publisher("/points", PointCloud2, queue_size=1)
    probe = Instrument("probe", "shaft", RADIUS, 0.1)
    time.sleep(1.0)
    probe.declare()
    start = time.time()
    sent = []  # (stamp ns) of every input sent, in order
    next_pose, next_cloud = start, start
    with session.lock:
        step0 = session.status.step
    statuses = []  # (state, text) of every ~status while the probe moves
    step_times = {}  # step -> its wall time (s), of the steps while the probe moves (a busy loop
    # repeats the last step's status)

    def on_status(m):
        statuses.append((m.state, m.text))
        if m.step > step0 and time.time() < start + args.duration:
            step_times.setdefault(m.step, m.step_time)

    rospy.Subscriber(f"{NODE}/status", SimulationStatus, on_status, queue_size=100)
    while time.time() < start + args.duration and not rospy.is_shutdown():
        now = time.time()
        if now >= next_pose:
            t = now - start
            phase = 2 * math.pi * t / PERIOD
            depth = PRESS[0] + (PRESS[1] - PRESS[0]) * (0.5 - 0.5 * math.cos(phase))
            tip = np.array([tumour[0] + 0.5 * SWEEP * math.sin(0.5 * phase), tumour[1], surface + RADIUS - depth])
            stamp = rospy.Time.from_sec(now)
            with session.lock:
                session.sent.add(stamp.to_nsec())
            probe.pose(tip, [0.0, 0.0, 1.0], stamp)
            sent.append(stamp.to_nsec())
            next_pose += 1.0 / POSE_RATE
        if camera is not None and now >= next_cloud:
            stamp = rospy.Time.from_sec(now)
            with session.lock:
                session.sent.add(stamp.to_nsec())
            cloud_pub.publish(point_cloud2.create_cloud_xyz32(Header(stamp=stamp, frame_id=FRAME),
                                                              camera.cloud(rng, [probe.tip])))
            sent.append(stamp.to_nsec())
            next_cloud += 1.0 / args.clouds
        time.sleep(max(0.0, min(next_pose, next_cloud if camera is not None else next_pose) - time.time()))
    end = time.time()
    time.sleep(0.5)
    with session.lock:
        steps = session.status.step - step0
    latencies = input_latencies(sorted(sent), list(meshes))
    moving = [t for t, _ in meshes if start <= t < end]
    lat = latencies * 1e3
    result = {
        "duration_s": round(end - start, 2),
        "clouds_per_s": args.clouds,
        "meshes_per_s": round(len(moving) / (end - start), 2),
        "frames_per_s": round(steps / (end - start), 2),
        "inputs_sent": len(sent),
        "status": {"messages": len(statuses), "iteration_cap": sum("iteration cap" in t for _, t in statuses),
                   "states": {w: sum(s == w for s, _ in statuses) for w in sorted({s for s, _ in statuses})}},
        "step_ms": {"median": round(1e3 * float(np.median(list(step_times.values()))), 1),
                    "p95": round(1e3 * float(np.percentile(list(step_times.values()), 95)), 1)} if step_times else None,
        "latency_ms": {"median": round(float(np.median(lat)), 1), "p95": round(float(np.percentile(lat, 95)), 1),
                       "max": round(float(lat.max()), 1)} if len(lat) else None,
    }
    print(json.dumps(result))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
