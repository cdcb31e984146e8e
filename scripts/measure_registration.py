#!/usr/bin/python3
"""Measures registration in a running liver_sim node (the liver phantom): point clouds of the
node's own surface, seen from the front (about 30% of it), with 1 mm noise and a bump of up to
8 mm that rises and falls under the right lobe, sent at 15 Hz for SECONDS: first sampled every
2 mm (about 6,000 points), then every 0.5 mm (about 90,000, a depth camera's density at 30% in
view). Reports for each: registered clouds per second, the latency from a cloud's stamp to the
first mesh marker that carries it, the uncertainty analyses that ran meanwhile; then the node's
filter time for a 1M-point cloud (from /diagnostics).

usage: scripts/measure_registration.sh [SECONDS]   (starts a master and the node, runs this)
"""
import struct
import sys
import time

import numpy as np
import rospy
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header
from visualization_msgs.msg import Marker

from liver_sim.msg import SimulationStatus, TargetCovariances


def surface_samples(marker, spacing, rng):
    """Points on the marker's front-facing triangles (seen from eye), uniform by area."""
    p = np.array([[q.x, q.y, q.z] for q in marker.points]).reshape(-1, 3, 3)
    centre = p.reshape(-1, 3).mean(axis=0)
    eye = centre + 0.25 * np.array([0.0, -1.0, 0.6]) / np.linalg.norm([0.0, -1.0, 0.6])
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    area = 0.5 * np.linalg.norm(n, axis=1)
    tri_centre = p.mean(axis=1)
    to_eye = eye - tri_centre
    axis = (centre - eye) / np.linalg.norm(centre - eye)
    angle = np.arccos(np.clip(-(to_eye / np.linalg.norm(to_eye, axis=1)[:, None]) @ axis, -1, 1))
    front = np.einsum("ij,ij->i", n, to_eye) > 0
    # The front faces nearest the view axis, up to 30% of the area (no occlusion test: the
    # phantom's front is convex enough for a throughput measurement).
    order = np.argsort(np.where(front, angle, np.inf))
    keep = order[np.cumsum(area[order]) <= 0.3 * area.sum()]
    counts = rng.poisson(area[keep] / spacing**2)
    tri = np.repeat(keep, counts)
    r1, r2 = np.sqrt(rng.random(len(tri))), rng.random(len(tri))
    return ((1 - r1)[:, None] * p[tri, 0] + (r1 * (1 - r2))[:, None] * p[tri, 1] + (r1 * r2)[:, None] * p[tri, 2])


def cloud_message(xyz):
    """A PointCloud2 of float32 x y z, packed at once (point_cloud2.create_cloud packs point by
    point: too slow for 90,000 points at 15 Hz)."""
    fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, n in enumerate("xyz")]
    return PointCloud2(header=Header(frame_id="liver", stamp=rospy.Time.now()), height=1, width=len(xyz),
                       fields=fields, is_bigendian=False, point_step=12, row_step=12 * len(xyz),
                       data=xyz.astype("<f4").tobytes(), is_dense=True)


def phase(state, analyses, pub, base, duration, rng):
    """Clouds of base (with noise and the bump) at 15 Hz for duration s; returns the report line."""
    bump = 8e-3 * np.exp(-np.sum((base[:, :2] - [-0.06, -0.03]) ** 2, axis=1) / (2 * 0.04**2))
    arrived = state["arrived"]
    sent, sent_at, t0 = [], [], time.time()
    first = state["status"][-1][1]
    received_before = int(state["diag"].get("point clouds received", 0))
    k = 0
    while time.time() - t0 < duration:
        # Built ahead of its slot and sent on it, as a camera sends its frames.
        s = 0.5 - 0.5 * np.cos(2 * np.pi * (k / 15.0) / 10.0)  # rises and falls over 10 s
        xyz = base + np.column_stack([0 * bump, 0 * bump, s * bump]) + rng.normal(0, 1e-3, base.shape)
        msg = cloud_message(xyz)
        time.sleep(max(0.0, t0 + k / 15.0 - time.time()))
        msg.header.stamp = rospy.Time.now()
        pub.publish(msg)
        sent.append(msg.header.stamp.to_nsec())
        sent_at.append(time.time())
        k += 1
    time.sleep(2.5)  # the last clouds registered, and a diagnostics period
    last = state["status"][-1][1]
    registered = last.clouds_registered - first.clouds_registered
    received = int(state["diag"].get("point clouds received", 0)) - received_before
    # Two clouds less than one of the node's frames apart (1/30 s) may reach the loop in one
    # frame, and the later replaces the earlier: a cloud that took this process longer than the
    # period to build is sent late, the next on time.
    bunched = sum(1 for a, b in zip(sent_at, sent_at[1:]) if b - a < 1 / 30)
    lat = np.array([(arrived[s] - s * 1e-9) * 1e3 for s in sent if s in arrived])
    ran = sum(t0 <= a < t0 + duration for a in list(analyses))  # the callback may add meanwhile
    if not len(lat):
        return f"{len(sent)} clouds sent, none shown on the mesh"
    return (f"{len(sent)} clouds of {len(base)} points sent at 15 Hz over {duration:.0f} s; "
            f"{bunched} sent within 1/30 s of the previous; received {received}, "
            f"registered {registered} ({registered / duration:.1f} per second); "
            f"cloud -> mesh latency over {len(lat)} clouds shown: median {np.median(lat):.0f} ms, "
            f"p95 {np.percentile(lat, 95):.0f} ms, max {lat.max():.0f} ms; "
            f"uncertainty analyses meanwhile {ran} (one per {duration / max(ran, 1):.1f} s); "
            f"RMS {last.registration_rms * 1e3:.2f} mm, {last.correspondences} correspondences, "
            f"refused inputs {last.rejected_inputs - first.rejected_inputs}")


def main():
    duration = float(sys.argv[1]) if len(sys.argv) > 1 else 30.0
    rospy.init_node("liver_sim_measure_registration")
    state = {"mesh": None, "status": [], "diag": {}, "arrived": {}}
    arrived = state["arrived"]

    def on_mesh(raw):
        # Unparsed but for the stamp (a mesh marker's thousands of points, parsed 15 times a
        # second, held this process up enough to send clouds late).
        _, secs, nsecs = struct.unpack_from("<III", raw._buff, 0)
        arrived.setdefault(secs * 10**9 + nsecs, time.time())
        if state["mesh"] is None:  # the rest shape: clouds are built from it
            state["mesh"] = Marker().deserialize(raw._buff)

    def on_diag(d):
        for s in d.status:
            if "liver model" in s.name:
                state["diag"] = {kv.key: kv.value for kv in s.values}

    rospy.Subscriber("/liver_sim/mesh", rospy.AnyMsg, on_mesh, queue_size=50)
    rospy.Subscriber("/liver_sim/status", SimulationStatus, lambda s: state["status"].append((time.time(), s)),
                     queue_size=100)
    rospy.Subscriber("/diagnostics", DiagnosticArray, on_diag, queue_size=10)
    analyses = set()  # the uncertainty analyses' stamps: the analysis must go on while clouds come
    rospy.Subscriber("/liver_sim/target_covariances", TargetCovariances,
                     lambda c: analyses.add(c.analysis_stamp.to_sec()), queue_size=10)
    pub = rospy.Publisher("/points", PointCloud2, queue_size=1)
    while state["mesh"] is None or not state["status"] or state["status"][-1][1].state != "idle":
        time.sleep(0.2)
    rng = np.random.default_rng(1)
    for name, spacing in (("surface samples", 2e-3), ("depth-camera density", 0.5e-3)):
        print(f"{name}: " + phase(state, analyses, pub, surface_samples(state["mesh"], spacing, rng), duration, rng))
        time.sleep(2.0)
    last = state["status"][-1][1]

    # A 1M-point cloud: the same patch, sampled 13x denser than the surface samples.
    pub.publish(cloud_message(surface_samples(state["mesh"], 0.15e-3, rng)))
    n0 = last.clouds_registered
    end = time.time() + 30
    while time.time() < end and state["status"][-1][1].clouds_registered == n0:
        time.sleep(0.1)
    time.sleep(2.5)  # a diagnostics period
    print(f"1M-point cloud: {state['diag'].get('last cloud size')} points, node filter time "
          f"{float(state['diag'].get('last cloud filter time (s)', 'nan')) * 1e3:.0f} ms")

if __name__ == "__main__":
    main()
