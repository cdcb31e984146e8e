#!/usr/bin/python3
"""The tools' JSON results parse with Python's json module as JSON (no NaN or Infinity, no raw
control characters) and carry names as given: a scene file and names with a tab, a quote, a
backslash and a non-ASCII letter; a number that is not finite (a fit whose every solve failed)
as null.

usage: test/scripts/tool_json_test.py SIMULATE CALIBRATE SCENES_DIR   (ctest runs it)
"""
import json
import os
import subprocess
import sys
import tempfile
import unittest

SIMULATE, CALIBRATE, SCENES = sys.argv[1:4]
ODD = 'a\tb "c" \\d é'  # what a file or probe name may hold


def strict_json(text):
    """The JSON value of `text`, refusing what Python's json accepts beyond JSON (NaN, Infinity)."""
    def refuse(constant):
        raise ValueError("not JSON: " + constant)
    return json.loads(text, parse_constant=refuse)


class ToolJson(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory(prefix="tool json\t")
        self.addCleanup(self.dir.cleanup)

    def scene(self, name, text=None):
        """The scene `name` of config/scenes copied to a file whose name holds ODD."""
        path = os.path.join(self.dir.name, ODD + " " + name)
        with open(os.path.join(SCENES, name)) as f, open(path, "w") as out:
            out.write(text(f.read()) if text else f.read())
        return path

    def test_simulate_names(self):
        quoted = json.dumps(ODD)  # also a YAML double-quoted scalar
        path = self.scene("aspiration_tube.yaml", lambda s: s.replace("name: centre", "name: " + quoted)
                          .replace("name: tube", "name: " + quoted))
        run = subprocess.run([SIMULATE, "--scene", path, "--quiet"], capture_output=True, text=True, timeout=300)
        self.assertEqual(run.returncode, 0, run.stderr)
        result = strict_json(run.stdout)
        self.assertEqual(result["scene"], path)
        self.assertEqual(list(result["probes"]), [ODD])
        self.assertEqual(list(result["instruments"]), [ODD])
        self.assertEqual(result["status"], "converged")

    def test_calibrate_failed_fit(self):
        path = self.scene("aspiration_tube.yaml")
        measured = os.path.join(self.dir.name, ODD + " measured.csv")
        run = subprocess.run([CALIBRATE, "--scene", path, "--synthesize", measured], capture_output=True, text=True,
                             timeout=300)
        self.assertEqual(run.returncode, 0, run.stderr)
        # Moduli beyond the model's bounds (1e9 Pa) within a factor 1e6 of the start: every solve
        # fails, the misfit is infinite.
        run = subprocess.run([CALIBRATE, "--scene", path, "--measured", measured, "--start-parenchyma", "1e20"],
                             capture_output=True, text=True, timeout=300)
        self.assertEqual(run.returncode, 3, run.stderr)
        result = strict_json(run.stdout)
        self.assertEqual((result["scene"], result["measured"]), (path, measured))
        fit = result["parenchyma"]
        self.assertEqual(fit["failed_evaluations"], fit["evaluations"])
        self.assertIsNone(fit["young_modulus"])
        self.assertIsNone(fit["rms_misfit"])
        self.assertIsNone(result["capsule"])  # not fitted after the parenchyma failed
        self.assertFalse(result["ok"])


if __name__ == "__main__":
    unittest.main(argv=sys.argv[:1])
