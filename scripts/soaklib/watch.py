"""Watches on the cores of the node and of the status receiver: processes of their own that tell
when a core, or the whole machine, stood still. Also how a child process's end report is taken."""
import multiprocessing
import os
import time


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
    core, and whether it had the top priority (record.py's `watches`)."""
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
            stalls.append([last + 0.005, now])
        last = now
        ticks += 1
        if ticks % 200 == 0 and not multiprocessing.parent_process().is_alive():
            return
    pipe.send({"stalls": stalls, "share": time.process_time() / (time.monotonic() - started), "top": top})


def receive(pipe, nothing):
    """What a child process sends at its end, or `nothing` when it sends nothing within 30 s or
    died unsent."""
    try:
        return pipe.recv() if pipe.poll(30) else nothing
    except EOFError:
        return nothing


class Watches:
    """A watch on each of `cores` (200 wake-ups a second: its share of the core is reported),
    started in fresh interpreters; one that cannot be placed sends nothing."""

    def __init__(self, spawn, cores, stop):
        self.cores = sorted(cores)
        self.children = []
        for core in self.cores:
            stalls_in, stalls_out = spawn.Pipe(duplex=False)
            watch = spawn.Process(target=watch_core, args=(core, stop, stalls_out), daemon=True)
            watch.start()
            stalls_out.close()  # the child's end: a watch that dies unsent ends recv() at once
            self.children.append((core, watch, stalls_in))

    def reports(self):
        """[core, report or None] for each watched core, once they were told to stop."""
        reports = [[core, receive(pipe, None)] for core, _, pipe in self.children]
        for _, watch, _ in self.children:
            watch.join(5)
        return reports
