"""One soak run against a running liver_sim_node: the load, the receivers and the core watches
started, a warm-up, the measured window, and the run's record (record.py) at the end."""
import multiprocessing
import os
import sys
import threading
import time
import xmlrpc.client

import rosgraph
import rospy

from . import record as rec
from .load import Load
from .receive import Receivers, receive_status
from .watch import Watches, receive, receiver_core


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
    """The process's resident memory (MB), or None once it has gone."""
    try:
        with open("/proc/%d/status" % pid) as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return None


def warm_up(pid, duration):
    """Waits while the node's memory grows to its working set as the first clouds pass (the
    allocator keeps what it frees at its high-water mark: keep_freed_memory, worker_pool.h), about
    60 clouds, which one core takes several seconds to register: at least min(10 s, a tenth of
    the run), then until RSS rose by less than 1 MB in 2 s, at most half the run. Returns how
    long it lasted (s)."""
    start = time.monotonic()
    time.sleep(min(10.0, 0.1 * duration))
    rss_before = rss_mb(pid)
    while time.monotonic() - start < 0.5 * duration:
        time.sleep(2.0)
        rss_now = rss_mb(pid)
        if rss_now is None or rss_before is None or rss_now - rss_before < 1.0:
            break
        rss_before = rss_now
    return time.monotonic() - start


def run(duration, points, max_gap):
    """Runs the soak for `duration` seconds (warm-up included) and returns its record."""
    receivers = Receivers()
    load = Load(points)
    rospy.wait_for_service("liver_sim/set_capsule", 60)
    node_rate = rospy.get_param("liver_sim/rate", 30.0)  # read once the node runs
    fault_every = rospy.get_param("liver_sim/test_fault_every", 0)
    pid = node_pid()
    if pid is None:
        raise RuntimeError("no liver_sim_node process")
    spawn = multiprocessing.get_context("spawn")  # a fresh interpreter: no rospy state of this one
    children_stop = spawn.Event()
    arrivals_in, arrivals_out = spawn.Pipe(duplex=False)
    receiver = spawn.Process(target=receive_status, args=(children_stop, arrivals_out), daemon=True)
    receiver.start()
    arrivals_out.close()  # the child's end: a receiver that dies unsent ends recv() at once
    watches = Watches(spawn, os.sched_getaffinity(pid) | {receiver_core()}, children_stop)
    deadline = time.monotonic() + 60
    while not receivers.statuses and time.monotonic() < deadline:
        time.sleep(0.1)
    stop = threading.Event()
    load.start(stop)
    warmup = warm_up(pid, duration)
    with receivers.lock:
        last = rec.Status(*receivers.statuses[-1])
    at_start = {"rejected_inputs": last.rejected_inputs, "faults": last.faults, "sent": dict(load.sent)}
    rss_start = rss_mb(pid)
    t_start = time.monotonic()
    next_report = t_start + 60
    while time.monotonic() - t_start < duration - warmup:
        time.sleep(0.5)
        if time.monotonic() >= next_report:
            next_report += 60
            print("soak: %.0f s, RSS %.1f MB, %d statuses" % (time.monotonic() - t_start + warmup, rss_mb(pid) or 0.0,
                                                                 len(receivers.statuses)), file=sys.stderr)
    rss_end = rss_mb(pid)
    t_end = time.monotonic()
    stop.set()
    children_stop.set()
    arrivals, collections = receive(arrivals_in, ([], []))
    watch_reports = watches.reports()
    receiver.join(5)
    load.join()
    with receivers.lock:
        return {
            "format": rec.FORMAT, "node_rate": node_rate, "fault_every": fault_every, "max_gap": max_gap,
            "warmup_s": warmup, "window": [t_start, t_end], "clock_offset": time.time() - time.monotonic(),
            "node_alive": os.path.exists("/proc/%d" % pid), "rss_mb": [rss_start, rss_end],
            "at_start": at_start, "sent": dict(load.sent), "statuses": list(receivers.statuses),
            "latency": list(receivers.latency), "non_finite_on": sorted(receivers.non_finite),
            "receiver": {"core": receiver_core(), "exit_code": receiver.exitcode, "arrivals": arrivals,
                         "collections": collections},
            "watches": watch_reports,
        }
