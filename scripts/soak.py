#!/usr/bin/python3
"""Soak test of a running liver_sim_node: point clouds at 30 Hz (100,000 points), instrument
poses at 1 kHz with NaN, absurd and jumping ones among them, a service call every second (every
other one out of range) and an instrument command every two seconds, for a given time
(scripts/soaklib/load.py). With the node's test hook ~test_fault_every set (soak.sh and soak.test
set it), faults are injected into its steps (exceptions, allocation failures, NaN, negative
pivots): each must be rolled back and counted; and every fifth injection holds a step up for
0.3 s, which the node's heartbeat must cover.

Reports: messages sent and handled, RSS of the node at start (after a warm-up that lasts until it
stops growing) and end, status messages and the largest gap between them (heartbeats included:
state "busy", sent while a frame has run a quarter of a frame and no status went out for one
frame), the longest frame (the largest gap between the stamps of the loop's own statuses), the
node's simulation frames against the frames its rate asks for (dropped frames), pose-to-mesh
latency early and late (a growing queue would make it grow), refused inputs, and the checks
(scripts/soaklib/judge.py says each). Exits 1 when a check fails. As a rostest (--rostest) only
the checks that hold at any speed are asserted, with a gap bound it can judge on a shared
machine: none above --max-gap seconds (the node's step time budget makes a frame at most one
Newton iteration and one stage long, about 0.7 s on the phantom with contact; a loop that hangs
or a step that runs its 16 stages through goes far beyond); the timing checks are printed.

--record FILE keeps the run's raw data (scripts/soaklib/record.py); --judge FILE judges such a
record again without a master or a node.

usage: scripts/soak.py [--duration S] [--points N] [--json FILE] [--record FILE]  (a master and the node running)
       scripts/soak.py --judge RECORD [--json FILE]                                (a recorded run)
       scripts/soak.sh [S]                                   (starts both, pinned; 600 s default)
       test/soak.test                                        (rostest: 30 s, --rostest)
"""
import argparse
import sys

import rospy

from soaklib import record, report


def soak(duration, points, max_gap, record_path=None):
    """A run's report; its record kept in `record_path` when given."""
    from soaklib import session

    if not rospy.core.is_initialized():
        rospy.init_node("liver_sim_soak", anonymous=True)
    run = session.run(duration, points, max_gap)
    if record_path:
        record.save(run, record_path)
    return report.report(run)


def rostest_main(duration, max_gap):
    import unittest

    import rostest

    class SoakTest(unittest.TestCase):
        def test_node_survives_soak(self):
            r = soak(duration, 100000, max_gap)
            print(report.text(r))
            for check, ok in r["checks"].items():
                self.assertTrue(ok, check + ": " + report.text(r))

    rospy.init_node("liver_sim_soak_test")
    rostest.rosrun("liver_sim", "soak", SoakTest)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=600.0, help="seconds (default 600)")
    ap.add_argument("--points", type=int, default=100000, help="points per cloud")
    ap.add_argument("--json", help="also write the report here")
    ap.add_argument("--record", help="also write the run's raw data here (soaklib/record.py)")
    ap.add_argument("--judge", metavar="RECORD", help="judge a recorded run instead of running one")
    ap.add_argument("--rostest", action="store_true", help="run as a rostest test node")
    ap.add_argument("--max-gap", type=float, default=10.0,
                    help="s: the largest ~status gap asserted at any speed (default 10)")
    args, _ = ap.parse_known_args(rospy.myargv()[1:])  # rostest adds --gtest_output=...
    if args.rostest:
        return rostest_main(args.duration, args.max_gap)
    r = report.report(record.load(args.judge)) if args.judge else soak(args.duration, args.points, args.max_gap,
                                                                        args.record)
    text = report.text(r)
    print(text)
    if args.json:
        with open(args.json, "w") as f:
            f.write(text + "\n")
    for name in report.failed(r):
        print("soak: FAILED: " + name, file=sys.stderr)
    return 1 if report.failed(r) else 0


if __name__ == "__main__":
    sys.exit(main())
