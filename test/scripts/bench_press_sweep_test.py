#!/usr/bin/python3
"""bench's press_sweep instruments file: the surface it presses from is the one under the probe
(the probe cube at rest: its top face, z = 15 mm, known from the scene), and each malformed file
is refused with exit status 1 and a message naming the file and the key (or the size bound).

usage: test/scripts/bench_press_sweep_test.py BENCH SCENES_DIR   (ctest runs it)
"""
import os
import re
import subprocess
import sys
import tempfile
import unittest

BENCH, SCENES = sys.argv[1:3]
CUBE = os.path.join(SCENES, "probe_cube.yaml")
KEYS = {"name": "probe", "type": "probe", "radius": "0.002", "above": "[0.0075, 0.0075]", "depth": "[0.0005, 0.001]",
        "sweep": "0.002", "period": "0.01", "rate": "1000", "duration": "0.003"}


class PressSweep(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory(prefix="press_sweep")
        self.addCleanup(self.dir.cleanup)

    def run_bench(self, padding="", **changes):
        keys = dict(KEYS, **changes)
        path = os.path.join(self.dir.name, "press.yaml")
        with open(path, "w") as f:
            f.write("press_sweep:\n" + "".join(f"  {k}: {v}\n" for k, v in keys.items() if v is not None) + padding)
        run = subprocess.run([BENCH, "--scene", CUBE, "--instruments", path, "--frames", "3", "--strategy",
                              "modified_newton:1:0"], capture_output=True, text=True, timeout=300)
        return path, run

    def test_presses_from_the_surface_under_the_probe(self):
        _, run = self.run_bench()
        self.assertEqual(run.returncode, 0, run.stderr)
        found = re.search(r"the surface lies at z = (\S+) m", run.stderr)
        self.assertIsNotNone(found, run.stderr)
        self.assertAlmostEqual(float(found.group(1)), 0.015, delta=1e-9)

    def test_malformed_files_are_refused_naming_the_key(self):
        for change, key in [({"radius": "abc"}, "radius"), ({"above": "[a, 1]"}, "above"),
                            ({"depth": "[0.002, 0.001]"}, "depth"), ({"radius": "10"}, "radius"),
                            ({"size": "1"}, "size"), ({"sweep": None}, "sweep"),
                            ({"above": "[1.0, 1.0]"}, "above")]:
            with self.subTest(change=change):
                path, run = self.run_bench(**change)
                self.assertEqual(run.returncode, 1, run.stderr)
                self.assertIn(path, run.stderr)
                self.assertIn(key, run.stderr)

    def test_a_file_over_1_mib_is_refused(self):
        # Valid YAML (comments) past the bound load_instruments sets on instruments files.
        path, run = self.run_bench(padding="# padding\n" * 120000)
        self.assertEqual(run.returncode, 1, run.stderr)
        self.assertIn(path, run.stderr)
        self.assertIn("1 MiB", run.stderr)


if __name__ == "__main__":
    unittest.main(argv=sys.argv[:1])
