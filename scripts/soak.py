#!/usr/bin/python3
"""Soak test of a running liver_sim_node: point clouds at 30 Hz (100,000 points), instrument
poses at 1 kHz (the probe pressing and circling on the phantom's right lobe), a service call
every second and an instrument command every two seconds, for a given time. Every 100th pose is
NaN and every 100th (another) absurd but finite (1e300 m), every 30th cloud empty, every other
set_capsule call out of range (alternately a modulus of -1 and of 1e300 Pa) and every other
command a radius of 1e9 m: the node must refuse and count them and keep going. Every 1000th pose
jumps 3 cm across the lobe and back (the step stages the move). With the node's test hook
~test_fault_every set (soak.sh and soak.test set it), faults are injected into its steps
(exceptions, allocation failures, NaN, negative pivots): each must be rolled back and counted;
and every fifth injection holds a step up for 0.3 s, which the node's heartbeat must cover.

Reports: messages sent and handled, RSS of the node at start (after a warm-up that lasts until it
stops growing) and end, status
messages and the largest gap between them (heartbeats included: state "busy", sent while a frame
has run a quarter of a frame and no status went out for one frame), the longest frame (the largest gap
between the stamps of the loop's own statuses), the node's simulation frames against the frames
its rate asks for (dropped frames), pose-to-mesh latency early and late (a growing queue would make it grow), refused
inputs. Every floating-point field of every message the node publishes on ~status, ~wrench,
~mesh, ~instruments and ~vessels is checked for NaN and infinity.

Exits 1 when a check fails. Checks that hold at any speed: the node is alive; ~status carries
every step (its step counter never skips one, a reset starting it again); RSS grew by at most
10% + 20 MB; nothing non-finite was published (every floating-point field of every message);
the refused inputs counted match those sent; with injected faults, some were counted, the
node went on stepping after each, heartbeats ("busy") came in frames of 0.2 s or more, at least
as many as the steps held up, and as
many held-up steps said so in their statuses as one injection in five (within 10% + 2).
Wall-clock checks: no ~status gap longer than two frames of the node's rate, between arrivals
at a process of its own that only receives ~status (this one builds clouds, which pauses its
receivers) and between the node's stamps. A watch on each core of the node and the receiver,
at the top real-time priority where allowed, notes when it was kept from running: where all
were at once, the machine stood still. Each gap is listed with how long the machine stood
still between the two stamps, and each receiver gap also with how much later than usual the
second status arrived and how long, from its stamp to its arrival, the receiver's core was
stalled and the receiver collected garbage. A stamp gap is judged without the machine's stalls
(only when every watch had the top priority); a receiver gap as the node's stamps apart
(without the machine's stalls) plus the second status's lateness beyond the receiver's own
pauses. The achieved
frame rate (frames counted by the status's step counter) at least 90% of that
rate over the time the injected delays leave (each held-up step's status says so; the rate over
the whole run is reported too); the late latency at most twice the early one + 0.2 s. As a rostest (--rostest) only the checks
that hold at any speed are asserted, and a gap bound it can judge on a shared machine: none
above --max-gap seconds (the node's step time budget makes a
frame at most one Newton iteration and one stage long, about 0.7 s on the phantom with contact;
a loop that hangs or a step that runs its 16 stages through goes far beyond); the others are
printed.

usage: scripts/soak.py [--duration S] [--points N] [--json FILE]      (a master and the node running)
       scripts/soak.sh [S]                                            (starts both, pinned; 600 s default)
       test/soak.test                                                 (rostest: 30 s, --rostest)
"""
import argparse
import gc
import json
import math
import multiprocessing
import os
import re
import struct
import sys
import threading
import time
import xmlrpc.client

import numpy as np
import rosgraph
import rospy
from geometry_msgs.msg import PoseStamped
from liver_sim.msg import SimulationStatus
from liver_sim.srv import SetCapsule
from sensor_msgs import point_cloud2
from sensor_msgs.msg import PointCloud2
from geometry_msgs.msg import WrenchStamped
from liver_sim.msg import InstrumentCommand
from std_msgs.msg import Header
from std_srvs.srv import Trigger

SURFACE_Z = 0.039   # m, sagged surface of the phantom's right lobe under the probe
RADIUS = 0.0025     # m, launch file's probe radius
HELD_UP_TEXT = "test hook: held up 0.3 s"  # in the status of a step the injected delay held up (step_guard.h)
HELD_UP_S = 0.3


def marker_fields(raw, o=0):
    """Stamp (s), floating-point fields and end offset of a serialized visualization_msgs/Marker
    starting at offset o: pose and scale, color, points, colors (read in place: the mesh has tens
    of thousands of points)."""
    secs, nsecs = struct.unpack_from("<II", raw, o + 4)
    o += 12
    for _ in range(2):  # header.frame_id, ns
        o += 4 + struct.unpack_from("<I", raw, o)[0]
    o += 12  # id, type, action
    pose_scale = np.frombuffer(raw, "<f8", 10, o)
    color = np.frombuffer(raw, "<f4", 4, o + 80)
    o += 80 + 16 + 8 + 1  # pose, scale, color, lifetime, frame_locked
    n = struct.unpack_from("<I", raw, o)[0]
    points = np.frombuffer(raw, "<f8", 3 * n, o + 4)
    o += 4 + 24 * n
    n = struct.unpack_from("<I", raw, o)[0]
    colors = np.frombuffer(raw, "<f4", 4 * n, o + 4)
    o += 4 + 16 * n
    for _ in range(2):  # text, mesh_resource
        o += 4 + struct.unpack_from("<I", raw, o)[0]
    return secs + 1e-9 * nsecs, (pose_scale, color, points, colors), o + 1  # mesh_use_embedded_materials


def marker_array_fields(raw):
    """The floating-point fields of every marker of a serialized visualization_msgs/MarkerArray."""
    fields, o = [], 4
    for _ in range(struct.unpack_from("<I", raw, 0)[0]):
        _, f, o = marker_fields(raw, o)
        fields.extend(f)
    return fields


def receive_status(stop, pipe):
    """A process of its own that only receives ~status and notes when each message arrived
    (monotonic clock, shared with the parent, and wall clock) and its stamp: the status gaps a
    subscriber sees.
    The soak's own process builds 100,000-point clouds and reads meshes, which pauses its
    receivers for up to 0.1-0.2 s (measured next to this receiver: no gap at those moments)."""
    # It shares its core with the soak's own process: ahead of it (where allowed), so that the
    # gaps measured are the node's and not this process's waits for the core.
    on_the_watched_core()
    rospy.init_node("liver_sim_soak_status", anonymous=True, argv=[], disable_signals=True)
    arrivals, collections = [], []
    # Python's garbage collections pause this process: the objects of the imports and rospy's
    # set-up are frozen out of them (they would make every full collection long), and each
    # collection is timed, so that a gap during one is told apart.
    gc.freeze()
    started = []

    def timed(phase, _info):
        if phase == "start":
            started[:] = [time.monotonic()]
        elif started:
            collections.append((started[0], time.monotonic()))

    gc.callbacks.append(timed)
    # TCP_NODELAY: without it, Nagle's algorithm may hold a small message for the peer's delayed
    # ACK. Arrival on both clocks: the monotonic one for gaps, the wall clock (the stamps') for
    # how late a status came.
    rospy.Subscriber("liver_sim/status", SimulationStatus,
                     lambda m: arrivals.append((time.monotonic(), time.time(), m.header.stamp.to_sec())),
                     queue_size=100, tcp_nodelay=True)
    while not stop.wait(1.0):
        if not multiprocessing.parent_process().is_alive():
            return
    pipe.send((list(arrivals), [c for c in collections if c[1] - c[0] > 0.005]))


def receiver_core():
    """The core of the status receiver: the first this process may use."""
    return min(os.sched_getaffinity(0))


def on_the_watched_core(core=None):
    """The status receiver and the core watches: on one core (by default the receiver's), ahead
    of the soak's own process and of the node (where allowed)."""
    os.sched_setaffinity(0, {receiver_core() if core is None else core})
    try:
        os.nice(-10)
    except PermissionError:
        pass


def watch_core(core, stop, pipe):
    """A process of its own on one core, at the top real-time priority where allowed (ahead of
    every other process there, a real-time node included), that only sleeps 5 ms at a time and
    notes from when it was due until it ran, when that was more than 10 ms: the times at which
    that core ran nothing (a stall of the core, not of a process on it). One runs on each core
    of the node and the receiver: where all of them were kept from running at once, the machine
    stood still (a virtual machine's host did not run it). Sends its stalls, its share of its
    core, and whether it had the top priority."""
    try:
        on_the_watched_core(core)
    except OSError:  # a core this process may not use (a container's cpuset)
        pipe.send(None)
        return
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(os.sched_get_priority_max(os.SCHED_FIFO)))
        top = True
    except OSError:  # no privilege: a real-time program or the node's real-time threads rank above
        top = False
    started = time.monotonic()
    stalls, last, ticks = [], started, 0
    while not stop.is_set():
        time.sleep(0.005)
        now = time.monotonic()
        if now - (last + 0.005) > 0.010:
            stalls.append((last + 0.005, now))
        last = now
        ticks += 1
        if ticks % 200 == 0 and not multiprocessing.parent_process().is_alive():
            return
    pipe.send((stalls, time.process_time() / (time.monotonic() - started), top))


def receive(pipe, nothing):
    """What a child process sends at its end, or `nothing` when it sends nothing within 30 s or
    died unsent."""
    try:
        return pipe.recv() if pipe.poll(30) else nothing
    except EOFError:
        return nothing


def enumerate_resets(window):
    """(segment, status) for each (arrival, status) of the window: the segment counts the resets
    before the status (the step counter starting again), so that (segment, step) names a step."""
    segment, last = 0, None
    for _, m in window:
        if last is not None and m.step < last:
            segment += 1
        last = m.step
        yield segment, m


def overlap(a, b, intervals):
    """How long the (start, end) intervals cover of [a, b] (s)."""
    return sum(max(0.0, min(b, e) - max(a, s)) for s, e in intervals)


def frame_in_progress_s(text):
    """How long a heartbeat's frame had been in progress, from its text (liver_sim_node.cpp)."""
    m = re.match(r"a frame in progress for (\d+) ms", text)
    return int(m.group(1)) / 1000.0 if m else 0.0


def rounded(record):
    """A record of times in seconds, to the millisecond (judged before rounding)."""
    return {k: round(v, 3) for k, v in record.items()}


def common_intervals(lists):
    """The times covered by an interval of every list (each list's intervals disjoint)."""
    common = lists[0] if lists else []
    for other in lists[1:]:
        common = [(max(s, t), min(e, u)) for s, e in common for t, u in other if max(s, t) < min(e, u)]
    return sorted(common)


def node_pid():
    """The pid of this master's liver_sim node, from the node itself (its slave API): other
    liver_sim nodes may run on the same computer (tests in parallel, other sessions)."""
    try:
        uri = rosgraph.Master("/soak").lookupNode(rospy.resolve_name("liver_sim"))
        code, _, pid = xmlrpc.client.ServerProxy(uri).getPid("/soak")
        return pid if code == 1 else None
    except (rosgraph.MasterError, OSError, xmlrpc.client.Error):
        return None


def rss_mb(pid):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


class Soak:
    def __init__(self, duration, points, max_gap):
        self.duration = duration
        self.max_gap = max_gap
        self.warmup = 0.0         # s, set when the warm-up ends
        self.lock = threading.Lock()
        self.sent = {"poses": 0, "nan_poses": 0, "absurd_poses": 0, "jumps": 0, "clouds": 0, "empty_clouds": 0,
                     "service_calls": 0, "refused_service_calls": 0, "resets": 0, "commands": 0, "huge_radii": 0}
        self.status = []          # (receive wall time, msg)
        self.latency = []         # (receive wall time, pose stamp -> mesh marker, s)
        self.meshes = 0
        self.non_finite = set()   # topics on which a NaN or infinity was published
        rng = np.random.default_rng(0)
        xyz = np.column_stack([rng.uniform(-0.1, 0.0, points), rng.uniform(-0.05, 0.03, points),
                               rng.uniform(0.02, 0.06, points)]).astype(np.float32)
        self.cloud = point_cloud2.create_cloud_xyz32(Header(frame_id="liver"), xyz)
        self.empty = point_cloud2.create_cloud_xyz32(Header(frame_id="liver"), [])
        self.pose_pub = rospy.Publisher("instruments/tool/pose", PoseStamped, queue_size=1)
        self.command_pub = rospy.Publisher("instrument_command", InstrumentCommand, queue_size=10)
        self.cloud_pub = rospy.Publisher("points", PointCloud2, queue_size=1)
        rospy.Subscriber("liver_sim/status", SimulationStatus, self.on_status, queue_size=100)
        rospy.Subscriber("liver_sim/wrench", WrenchStamped, self.on_wrench, queue_size=100)
        rospy.Subscriber("liver_sim/mesh", rospy.AnyMsg, self.on_mesh, queue_size=2)
        rospy.Subscriber("liver_sim/vessels", rospy.AnyMsg, self.on_marker, callback_args="vessels", queue_size=2)
        rospy.Subscriber("liver_sim/instruments", rospy.AnyMsg, self.on_marker, callback_args="instruments", queue_size=2)

    def on_status(self, m):
        with self.lock:
            self.status.append((time.monotonic(), m))
            floats = [getattr(m, name) for name, kind in zip(m.__slots__, m._slot_types) if kind == "float64"]
            if not all(math.isfinite(v) for v in floats):
                self.non_finite.add("status")

    def on_wrench(self, m):
        w = m.wrench
        if not all(math.isfinite(v) for v in (w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z)):
            with self.lock:
                self.non_finite.add("wrench")

    def on_marker(self, m, topic):
        try:
            fields = marker_array_fields(m._buff) if topic == "instruments" else marker_fields(m._buff)[1]
        except (struct.error, ValueError):  # a message this check cannot read fails it
            fields = [np.array([np.nan])]
        if not all(np.isfinite(f).all() for f in fields):
            with self.lock:
                self.non_finite.add(topic)

    def on_mesh(self, m):
        now = rospy.Time.now().to_sec()
        stamp, fields, _ = marker_fields(m._buff)
        with self.lock:
            self.meshes += 1
            if stamp > 0:
                self.latency.append((time.monotonic(), now - stamp))
            if not all(np.isfinite(f).all() for f in fields):
                self.non_finite.add("mesh")

    def poses(self, stop):
        rate = rospy.Rate(1000)
        t0 = time.monotonic()
        while not stop.is_set() and not rospy.is_shutdown():
            t = time.monotonic() - t0
            p = PoseStamped(header=Header(stamp=rospy.Time.now(), frame_id="liver"))
            # Circles of 3 mm at 0.5 Hz, pressing 3-5 mm.
            p.pose.position.x = -0.05 + 0.003 * math.cos(math.pi * t)
            p.pose.position.y = -0.02 + 0.003 * math.sin(math.pi * t)
            p.pose.position.z = SURFACE_Z + RADIUS - 0.004 - 0.001 * math.sin(0.3 * t)
            p.pose.orientation.w = 1.0
            self.sent["poses"] += 1
            if self.sent["poses"] % 1000 < 200:  # a jump of 3 cm across the lobe, 0.2 s there
                p.pose.position.y += 0.03
                self.sent["jumps"] += self.sent["poses"] % 1000 == 0
            if self.sent["poses"] % 100 == 0:
                p.pose.position.x = float("nan")
                self.sent["nan_poses"] += 1
            elif self.sent["poses"] % 100 == 50:
                p.pose.position.x = 1e300
                self.sent["absurd_poses"] += 1
            self.pose_pub.publish(p)
            rate.sleep()

    def clouds(self, stop):
        rate = rospy.Rate(30)
        while not stop.is_set() and not rospy.is_shutdown():
            self.sent["clouds"] += 1
            msg = self.cloud
            if self.sent["clouds"] % 30 == 0:
                msg = self.empty
                self.sent["empty_clouds"] += 1
            msg.header.stamp = rospy.Time.now()
            self.cloud_pub.publish(msg)
            rate.sleep()

    def services(self, stop):
        set_capsule = rospy.ServiceProxy("liver_sim/set_capsule", SetCapsule)
        reset = rospy.ServiceProxy("liver_sim/reset", Trigger)
        k = 0
        while not stop.wait(1.0):
            k += 1
            if k % 10 == 0:
                reset()
                self.sent["resets"] += 1
            elif k % 2:
                r = set_capsule(True, 3.0e6 if k % 4 == 1 else 4.0e6, 93e-6, 0.45)  # valid: E alternates
                self.sent["service_calls"] += 1
                if not r.success:
                    raise RuntimeError("valid set_capsule refused: " + r.message)
            else:
                r = set_capsule(True, -1.0 if k % 4 == 0 else 1e300, 93e-6, 0.45)  # out of range: refused
                self.sent["service_calls"] += 1
                self.sent["refused_service_calls"] += not r.success
            if k % 2 == 0:  # a probe radius, alternately valid and absurd (refused)
                huge = k % 4 == 0
                self.command_pub.publish(InstrumentCommand(name="tool", radius=1e9 if huge else 0.0025))
                self.sent["commands"] += 1
                self.sent["huge_radii"] += huge

    def run(self):
        rospy.wait_for_service("liver_sim/set_capsule", 60)
        self.node_rate = rospy.get_param("liver_sim/rate", 30.0)  # read once the node runs
        self.fault_every = rospy.get_param("liver_sim/test_fault_every", 0)
        pid = node_pid()
        if pid is None:
            raise RuntimeError("no liver_sim_node process")
        spawn = multiprocessing.get_context("spawn")  # a fresh interpreter: no rospy state of this one
        receiver_stop = spawn.Event()
        arrivals_in, arrivals_out = spawn.Pipe(duplex=False)
        receiver = spawn.Process(target=receive_status, args=(receiver_stop, arrivals_out), daemon=True)
        receiver.start()
        arrivals_out.close()  # the child's end: a receiver that dies unsent ends recv() at once
        # A core watch on each core of the node and of the receiver (200 wake-ups a second: its
        # share of the core is reported); one that cannot be placed sends nothing.
        watches = []
        self.watched_cores = sorted(os.sched_getaffinity(pid) | {receiver_core()})
        for core in self.watched_cores:
            stalls_in, stalls_out = spawn.Pipe(duplex=False)
            watch = spawn.Process(target=watch_core, args=(core, receiver_stop, stalls_out), daemon=True)
            watch.start()
            stalls_out.close()
            watches.append((core, watch, stalls_in))
        deadline = time.monotonic() + 60
        while not self.status and time.monotonic() < deadline:
            time.sleep(0.1)
        stop = threading.Event()
        threads = [threading.Thread(target=f, args=(stop,), daemon=True) for f in (self.poses, self.clouds, self.services)]
        for t in threads:
            t.start()
        # Warm-up: the node's memory grows to its working set as the first clouds pass (the
        # allocator keeps what it frees at its high-water mark: keep_freed_memory, worker_pool.h),
        # about 60 clouds, which one core takes several seconds to register. The memory check
        # starts from that plateau: at least min(10 s, a tenth of the run), then until RSS rose
        # by less than 1 MB in 2 s, at most half the run.
        warmup_start = time.monotonic()
        time.sleep(min(10.0, 0.1 * self.duration))
        rss_before = rss_mb(pid)
        while time.monotonic() - warmup_start < 0.5 * self.duration:
            time.sleep(2.0)
            rss_now = rss_mb(pid)
            if rss_now - rss_before < 1.0:
                break
            rss_before = rss_now
        warmup = self.warmup = time.monotonic() - warmup_start
        with self.lock:
            rejected_start = self.status[-1][1].rejected_inputs
            faults_start = self.status[-1][1].faults
        sent_start = dict(self.sent)
        rss_start = rss_mb(pid)
        t_start = time.monotonic()
        next_report = t_start + 60
        while time.monotonic() - t_start < self.duration - warmup:
            time.sleep(0.5)
            if time.monotonic() >= next_report:
                next_report += 60
                print("soak: %.0f s, RSS %.1f MB, %d statuses" % (time.monotonic() - t_start + warmup, rss_mb(pid),
                                                                     len(self.status)), file=sys.stderr)
        rss_end = rss_mb(pid) if os.path.exists("/proc/%d" % pid) else float("nan")
        t_end = time.monotonic()
        stop.set()
        receiver_stop.set()
        arrivals, collections = receive(arrivals_in, ([], []))
        watch_reports = {core: receive(pipe, None) for core, _, pipe in watches}
        receiver.join(5)
        for _, watch, _ in watches:
            watch.join(5)
        for t in threads:
            t.join(5)
        return self.report(pid, sent_start, rejected_start, faults_start, rss_start, rss_end, t_start, t_end, arrivals,
                           receiver.exitcode, watch_reports, collections)

    def report(self, pid, sent_start, rejected_start, faults_start, rss_start, rss_end, t_start, t_end, arrivals,
               receiver_exit, watch_reports, collections):
        # Between arrivals at the receiver of its own (receive_status), and between the node's
        # stamps (when it published).
        arrived = [a for a in arrivals if t_start <= a[0] <= t_end]
        received = [t for t, _, _ in arrived]
        gaps = [b - a for a, b in zip(received, received[1:])]
        # The core watches (watch_core): the receiver's core's stalls, and the machine's (the
        # watched cores' at once; none unless every watch ran, all at the top priority).
        watches = [watch_reports.get(core) for core in self.watched_cores]
        judged = bool(watches) and all(w is not None and w[2] for w in watches)
        machine = common_intervals([w[0] for w in watches]) if judged else []
        stalls = (watch_reports.get(receiver_core()) or [[]])[0]
        # The node stamps on the wall clock; each arrival was noted on both clocks.
        wall_minus_monotonic = (float(np.median([wall - mono for mono, wall, _ in arrivals])) if arrivals
                                else time.time() - time.monotonic())

        def on_the_monotonic_clock(stamp):
            return stamp - wall_minus_monotonic

        def machine_stalled(stamp_a, stamp_b):
            return overlap(on_the_monotonic_clock(stamp_a), on_the_monotonic_clock(stamp_b), machine)

        # Each receiver gap over two frames, told apart: how far apart the node stamped the two
        # statuses and how long the machine stood still between the stamps; how much later than
        # usual the second arrived (wall-clock arrival - stamp, over its median), and how long,
        # from its stamp to its arrival, the receiver's core was stalled and the receiver
        # collected garbage. The node's part: the stamps apart while the machine ran, and the
        # lateness beyond those pauses of the receiver's (a status the node stamped and then
        # sent late is the node's).
        usual = float(np.median([wall - stamp for _, wall, stamp in arrived])) if arrived else 0.0
        late_by = [wall - stamp - usual for _, wall, stamp in arrived]
        long_gaps = []
        for (a, _, sa), (b, wb, sb) in zip(arrived, arrived[1:]):
            if b - a <= 2.0 / self.node_rate:
                continue
            g = {"at_s": a - t_start, "gap_s": b - a, "stamps_apart_s": sb - sa,
                 "machine_stalled_between_the_stamps_s": machine_stalled(sa, sb),
                 "delivered_late_by_s": wb - sb - usual,
                 "receiver_core_stalled_s": overlap(on_the_monotonic_clock(sb), b, stalls),
                 "receiver_collecting_garbage_s": overlap(on_the_monotonic_clock(sb), b, collections)}
            g["the_node's_part_s"] = (g["stamps_apart_s"] - g["machine_stalled_between_the_stamps_s"] + max(
                0.0, g["delivered_late_by_s"] - max(g["receiver_core_stalled_s"], g["receiver_collecting_garbage_s"])))
            long_gaps.append(g)
        stalls = [(s, e) for s, e in stalls if t_start <= s <= t_end]
        machine_in_window = [(s, e) for s, e in machine if t_start <= s <= t_end]
        collections = [(s, e) for s, e in collections if t_start <= s <= t_end]
        with self.lock:
            window = [(t, m) for t, m in self.status if t_start <= t <= t_end]
            stamps = [m.header.stamp.to_sec() for _, m in window]
            # Between the loop's own statuses, heartbeats ("busy") left out: the longest frame.
            own = [m.header.stamp.to_sec() for _, m in window if m.state != "busy"]
            frame_gaps = [b - a for a, b in zip(own, own[1:])]
            busy = sum(1 for _, m in window if m.state == "busy")
            # Heartbeats in a frame 0.2 s long or longer: each injected 0.3 s delay has some.
            busy_long = sum(1 for _, m in window if m.state == "busy" and frame_in_progress_s(m.text) >= 0.2)
            # Steps whose status never came: the counter advanced by more than one (a reset
            # starts it again at 1; an idle node repeats its last step).
            skipped = sum(b.step - a.step - 1 if b.step > a.step else b.step - 1
                          for (_, a), (_, b) in zip(window, window[1:])
                          if b.step > a.step + 1 or (b.step < a.step and b.step > 1))
            faulted = [i for i, (_, m) in enumerate(window) if m.state == "fault"]
            # Stepping on after the last fault: the statuses that came after the window count
            # too (a fault can be the window's last status).
            later = [m for t, m in self.status if t >= t_start][faulted[-1] + 1:] if faulted else []
            steps_after_fault = sum(1 for m in later if m.state not in ("fault", "busy"))
            lat = [(t, l) for t, l in self.latency if t_start <= t <= t_end]
        stamp_gaps = [b - a for a, b in zip(stamps, stamps[1:])]
        # Each stamp gap over two frames, and the machine's stall within it: the node's part is
        # the rest.
        long_stamp_gaps = [{"at_s": on_the_monotonic_clock(a) - t_start, "stamps_apart_s": b - a,
                            "machine_stalled_s": machine_stalled(a, b)}
                           for a, b in zip(stamps, stamps[1:]) if b - a > 2.0 / self.node_rate]
        span = t_end - t_start
        third = span / 3
        early = [l for t, l in lat if t < t_start + third]
        late = [l for t, l in lat if t >= t_end - third]
        sent = {k: self.sent[k] - sent_start[k] for k in self.sent}
        last = window[-1][1] if window else None
        # Frames: the loop asks for ~rate frames per second; a step that takes longer than a
        # frame makes the loop miss frames. Counted by the step counter (a reset starts it again
        # at 1; heartbeats and repeated statuses repeat a step).
        frames = sum(b.step - a.step if b.step >= a.step else b.step for (_, a), (_, b) in zip(window, window[1:]))
        achieved = frames / span if span > 0 else 0.0
        # The injected delays stop the loop on purpose, 0.3 s each: the rate the node keeps is
        # judged over the time they leave. The node tells each held-up step (its status may be
        # sent more than once).
        held_steps = len({(i, m.step) for i, m in enumerate_resets(window) if HELD_UP_TEXT in m.text})
        held = HELD_UP_S * held_steps
        kept = frames / (span - held) if span > held else 0.0
        # One injection in five is a delay (those that meet a step without an update wait for one).
        delays_expected = frames / (5 * self.fault_every) if self.fault_every > 0 else 0.0
        r = {
            "warmup_s": round(self.warmup, 1),
            "duration_s": round(span, 1),
            "node_alive": os.path.exists("/proc/%d" % pid),
            "sent": sent,
            "rss_mb": {"start": round(rss_start, 1), "end": round(rss_end, 1)},
            "status_messages": len(window),
            "status_messages_at_the_receiver": len(received),
            "status_receiver_exit_code": receiver_exit,
            "status_max_gap_s": round(max(gaps), 3) if gaps else None,
            # How much later than usual (the median) statuses arrived after their stamps.
            "status_delivered_late_by_s": {q: round(float(np.percentile(late_by, p)), 4) if late_by else None
                                           for q, p in (("p99", 99), ("p99.9", 99.9), ("max", 100))},
            "status_gaps_over_two_frames": sum(1 for g in gaps if g > 2.0 / self.node_rate),
            "status_gaps_over_two_frames_apart": [rounded(g) for g in long_gaps],
            "receiver_garbage_collections_over_5ms": {"count": len(collections),
                                                      "max_s": round(max((e - s for s, e in collections), default=0.0), 3)},
            "receiver_core_stalls_over_10ms": {"count": len(stalls),
                                               "max_s": round(max((e - s for s, e in stalls), default=0.0), 3)},
            "cores_watched": {"cores": self.watched_cores,
                              "watched_at_the_top_priority": [bool(w and w[2]) for w in watches],
                              "machine_stalls_judged": judged,
                              "processor_share_max": round(max((w[1] for w in watches if w), default=0.0), 4)},
            # Times at which every watched core had been kept from running for over 10 ms.
            "machine_stalls": {"count": len(machine_in_window),
                               "max_s": round(max((e - s for s, e in machine_in_window), default=0.0), 3),
                               "total_s": round(sum(e - s for s, e in machine_in_window), 3)},
            "status_max_stamp_gap_s": round(max(stamp_gaps), 3) if stamp_gaps else None,
            "status_stamp_gaps_over_two_frames": len(long_stamp_gaps),
            "status_stamp_gaps_over_two_frames_apart": [rounded(g) for g in long_stamp_gaps],
            "status_busy": busy,
            "status_busy_in_a_frame_of_0.2_s_or_more": busy_long,
            "longest_frame_s": round(max(frame_gaps), 3) if frame_gaps else None,
            "status_steps_skipped": skipped,
            "mesh_markers": len(lat),
            "latency_s": {"early_median": round(float(np.median(early)), 3) if early else None,
                          "late_median": round(float(np.median(late)), 3) if late else None,
                          "max": round(max(l for _, l in lat), 3) if lat else None},
            "frames": {"asked_hz": self.node_rate, "achieved_hz": round(achieved, 2),
                       "dropped": int(round(max(0.0, self.node_rate * span - frames))),
                       "done": frames,
                       "held_up_on_purpose": {"steps": held_steps, "s": round(held, 1),
                                              "expected_steps": round(delays_expected, 1)},
                       "achieved_outside_the_injected_delays_hz": round(kept, 2)},
            "refused_inputs_counted": (last.rejected_inputs - rejected_start) if last else None,
            "faults": {"injected_every_frames": self.fault_every,
                       "counted": (last.faults - faults_start) if last else None,
                       "fault_statuses": sum(1 for _, m in window if m.state == "fault"),
                       "steps_after_the_last_fault": steps_after_fault},
            "non_finite_published_on": sorted(self.non_finite),
        }
        halves = [sum(1 for t, _ in window if t < t_start + span / 2), sum(1 for t, _ in window if t >= t_start + span / 2)]
        checks = {
            "node alive": r["node_alive"],
            "status kept flowing (messages in both halves of the run)": min(halves) > 0,
            "the status receiver (a process of its own) received statuses": len(received) > 1,
            "memory flat (end <= 1.1 start + 20 MB)": rss_end <= 1.1 * rss_start + 20,
            "every step's status received (the step counter never skips)": skipped == 0,
            "nothing non-finite published (status, wrench, mesh, instruments, vessels)": not self.non_finite,
            "refused inputs counted (all refused service calls, at most every invalid message)":
                last is not None and sent["refused_service_calls"] <= r["refused_inputs_counted"]
                <= sent["refused_service_calls"] + sent["nan_poses"] + sent["absurd_poses"] + sent["empty_clouds"]
                + sent["huge_radii"] + 2,
            "injected faults counted, and the node stepped on after them":
                self.fault_every == 0 or (r["faults"]["counted"] or 0) > 0 and steps_after_fault > 0,
            # A held-up step lasts nine frames of 30 Hz: without the heartbeat, no "busy" at all
            # (tried: the heartbeat disabled fails the 30 s rostest here, 0 busy of 530 statuses).
            # Counted in frames of 0.2 s or more: a heartbeat may also come in a normal frame.
            "heartbeats while the injected delays held steps up": self.fault_every == 0
            or 0 < held_steps <= busy_long,
            "the held-up steps' statuses say so (as many as one injection in five, within 10% + 2)":
                abs(held_steps - delays_expected) <= 0.1 * delays_expected + 2,
            "no status gap above %g s" % self.max_gap: bool(gaps) and max(gaps) <= self.max_gap,
        }
        # Wall-clock checks: judged by the standalone soak (scripts/soak.sh, a quiet pinned
        # machine), reported but not asserted by the 30 s rostest (shared, noisy, or sanitized).
        timing = {
            "status gaps <= two frames at the receiver (the node's part)": bool(gaps) and all(
                g["the_node's_part_s"] <= 2.0 / self.node_rate for g in long_gaps),
            "status stamps (when the node published) <= two frames apart while the machine ran": bool(stamp_gaps)
            and all(g["stamps_apart_s"] - g["machine_stalled_s"] <= 2.0 / self.node_rate for g in long_stamp_gaps),
            "frame rate >= 90% of the node's rate (outside the injected delays)": kept >= 0.9 * self.node_rate,
            "no growing queue (late latency <= 2 x early + 0.2 s)": bool(early) and bool(late)
            and np.median(late) <= 2 * np.median(early) + 0.2,
        }
        r["timing_checks"] = {k: bool(v) for k, v in timing.items()}
        r["checks"] = {k: bool(v) for k, v in checks.items()}
        return r


def rostest_main(duration, max_gap):
    import unittest

    import rostest

    class SoakTest(unittest.TestCase):
        def test_node_survives_soak(self):
            report = Soak(duration, 100000, max_gap).run()
            print(json.dumps(report, indent=2))
            for check, ok in report["checks"].items():
                self.assertTrue(ok, check + ": " + json.dumps(report))

    rospy.init_node("liver_sim_soak_test")
    rostest.rosrun("liver_sim", "soak", SoakTest)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=600.0, help="seconds (default 600)")
    ap.add_argument("--points", type=int, default=100000, help="points per cloud")
    ap.add_argument("--json", help="also write the report here")
    ap.add_argument("--rostest", action="store_true", help="run as a rostest test node")
    ap.add_argument("--max-gap", type=float, default=10.0,
                    help="s: the largest ~status gap asserted at any speed (default 10)")
    args, _ = ap.parse_known_args(rospy.myargv()[1:])  # rostest adds --gtest_output=...
    if args.rostest:
        return rostest_main(args.duration, args.max_gap)
    rospy.init_node("liver_sim_soak", anonymous=True)
    report = Soak(args.duration, args.points, args.max_gap).run()
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        with open(args.json, "w") as f:
            f.write(text + "\n")
    failed = [k for k, ok in list(report["checks"].items()) + list(report["timing_checks"].items()) if not ok]
    for k in failed:
        print("soak: FAILED: " + k, file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
