"""What the soak receives from the node: every ~status in a receiver process of its own (the
gaps a subscriber sees), and in the soak's own process every ~status, the pose-to-mesh latency
and whether any floating-point field of any message on ~status, ~wrench, ~mesh, ~instruments and
~vessels was NaN or infinite."""
import gc
import multiprocessing
import struct
import threading
import time

import genpy
import numpy as np
import rospy
from geometry_msgs.msg import WrenchStamped
from liver_sim.msg import SimulationStatus
from visualization_msgs.msg import Marker, MarkerArray

from .fields import mesh_marker_fields, non_finite
from .record import status_row
from .watch import on_the_watched_core


class Receivers:
    """The soak's own subscriptions (callbacks on rospy's threads)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.statuses = []        # record.py's rows, in arrival order
        self.latency = []         # [arrival, pose stamp -> mesh marker (s)]
        self.non_finite = set()   # topics on which a NaN or infinity was published
        rospy.Subscriber("liver_sim/status", SimulationStatus, self.on_status, queue_size=100)
        rospy.Subscriber("liver_sim/wrench", WrenchStamped, self.on_wrench, queue_size=100)
        rospy.Subscriber("liver_sim/mesh", rospy.AnyMsg, self.on_mesh, queue_size=2)
        rospy.Subscriber("liver_sim/vessels", rospy.AnyMsg, self.on_marker, callback_args=("vessels", Marker),
                         queue_size=2)
        rospy.Subscriber("liver_sim/instruments", rospy.AnyMsg, self.on_marker,
                         callback_args=("instruments", MarkerArray), queue_size=2)

    def on_status(self, m):
        with self.lock:
            self.statuses.append(status_row(time.monotonic(), m))
            if non_finite(m):
                self.non_finite.add("status")

    def on_wrench(self, m):
        if non_finite(m):
            with self.lock:
                self.non_finite.add("wrench")

    def on_marker(self, raw, topic_and_type):
        topic, kind = topic_and_type
        try:
            bad = non_finite(kind().deserialize(raw._buff))
        except genpy.DeserializationError:  # a message this check cannot read fails it
            bad = True
        if bad:
            with self.lock:
                self.non_finite.add(topic)

    def on_mesh(self, raw):
        now = rospy.Time.now().to_sec()
        try:
            stamp, fields = mesh_marker_fields(raw._buff)
            bad = not all(np.isfinite(f).all() for f in fields)
        except (struct.error, ValueError):  # a message this check cannot read fails it
            stamp, bad = 0.0, True
        with self.lock:
            if stamp > 0:
                self.latency.append([time.monotonic(), now - stamp])
            if bad:
                self.non_finite.add("mesh")


def receive_status(stop, pipe):
    """A process of its own that only receives ~status and notes when each message arrived
    (monotonic clock, shared with the parent, and wall clock) and its stamp: the status gaps a
    subscriber sees. The soak's own process builds 100,000-point clouds and reads meshes, which
    pauses its receivers for up to 0.1-0.2 s (measured next to this receiver: no gap at those
    moments). Sends record.py's receiver `arrivals` and `collections`."""
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
            collections.append([started[0], time.monotonic()])

    gc.callbacks.append(timed)
    # TCP_NODELAY: without it, Nagle's algorithm may hold a small message for the peer's delayed
    # ACK. Arrival on both clocks: the monotonic one for gaps, the wall clock (the stamps') for
    # how late a status came.
    rospy.Subscriber("liver_sim/status", SimulationStatus,
                     lambda m: arrivals.append([time.monotonic(), time.time(), m.header.stamp.to_sec()]),
                     queue_size=100, tcp_nodelay=True)
    while not stop.wait(1.0):
        if not multiprocessing.parent_process().is_alive():
            return
    pipe.send((list(arrivals), [c for c in collections if c[1] - c[0] > 0.005]))
