#!/usr/bin/python3
"""The OR demo as users play it (launch/or_demo.launch, scripts/run.sh), at twice its speed against
the node of test/or_demo.test: it must end with its summary, and its own check must pass: the probe
presses straight above the tumour (scripts/or_demo.py exits 1 when the pressing tip is more than
5 mm across from the tumour, as when it pressed the other lobe, or below it)."""
import os
import subprocess
import sys
import unittest

import rostest

SCRIPT = os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", "scripts", "or_demo.py")


class OrDemo(unittest.TestCase):
    def test_probe_presses_above_the_tumour(self):
        run = subprocess.run([sys.executable, SCRIPT, "--speed", "2"], capture_output=True, text=True, timeout=150)
        sys.stdout.write(run.stdout[-3000:] + run.stderr[-2000:])
        self.assertEqual(run.returncode, 0, run.stderr[-500:])
        self.assertIn("summary: the probe pressed with", run.stdout)


if __name__ == "__main__":
    rostest.rosrun("liver_sim", "or_demo", OrDemo)
