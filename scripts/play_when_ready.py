#!/usr/bin/python3
"""Plays a bag into the node once the node has reached its pre-operative equilibrium: waits for
the node's ~status to say `converged` (or `idle` after a step: an equilibrium held since), when the
node has also taken that state as its colour reference, then becomes `rosbag play --clock`.
launch/playback.launch starts it beside the node.

usage: play_when_ready.py BAG [--rate F] [--status TOPIC] [--timeout S]
  --status   the node's status topic (default /liver_sim/status)
  --timeout  wall seconds to wait; past them the bag plays anyway, with a warning (default 120)
"""
import argparse
import os
import sys
import threading

import rospy
from liver_sim.msg import SimulationStatus


def at_equilibrium(status):
    return status.state == "converged" or (status.state == "idle" and status.step > 0)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bag")
    ap.add_argument("--rate", type=float, default=1.0, help="playback speed factor (> 0)")
    ap.add_argument("--status", default="/liver_sim/status")
    ap.add_argument("--timeout", type=float, default=120.0)
    args = ap.parse_args(rospy.myargv()[1:])
    if not os.path.isfile(args.bag):
        sys.exit(f"play_when_ready: {args.bag}: no such file")
    if not args.rate > 0:
        sys.exit("play_when_ready: --rate must be > 0")
    rospy.init_node("play_when_ready", anonymous=True, disable_signals=True)
    ready = threading.Event()
    sub = rospy.Subscriber(args.status, SimulationStatus, lambda s: at_equilibrium(s) and ready.set())
    # Wall time: with use_sim_time the clock stands still until the bag plays it.
    if ready.wait(args.timeout):
        rospy.loginfo("play_when_ready: the node is at its equilibrium; playing %s", args.bag)
    else:
        rospy.logwarn("play_when_ready: no equilibrium on %s within %g s; playing %s anyway", args.status,
                      args.timeout, args.bag)
    sub.unregister()
    rospy.signal_shutdown("playing")
    sys.stdout.flush()  # exec drops what is still buffered
    sys.stderr.flush()
    os.execvp("rosbag", ["rosbag", "play", "--clock", "--rate", repr(args.rate), args.bag])


if __name__ == "__main__":
    main()
