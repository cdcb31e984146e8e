#!/usr/bin/python3
"""One-shot registration against a truth of another law (doc/registration.md, "Truths of another
law"): the phantom's anatomy deformed by a large-strain neo-Hookean solver under a retractor's
prescribed displacement (scripts/make_neohookean_truth.py, its own mesh), registered with the
phantom's scene by register_insilico from its anterior and superior views with 1 mm sensor noise;
the errors at the truth's 2,794 interior nodes and how well the targets' covariances cover them.

Held out: the one-shot's `support` was chosen on the packing case (and the Open-CAS case's
tuning views), not on this one. A check against a truth our own code wrote, but with another
law, mesh and solver: not data nobody here made.

usage: test/scripts/neohookean_registration_test.py REGISTER_INSILICO   (ctest runs it)
"""
import csv
import os
import subprocess
import sys
import tempfile
import unittest

REGISTER_INSILICO = sys.argv[1]
REPO = os.path.realpath(os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", ".."))


class NeoHookeanRegistration(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.TemporaryDirectory(prefix="neohookean")
        subprocess.run([sys.executable, os.path.join(REPO, "scripts", "make_neohookean_truth.py"), "--out", cls.dir.name,
                        "--case", "retractor", "--quiet"], check=True)
        rows = os.path.join(cls.dir.name, "rows.csv")
        subprocess.run([REGISTER_INSILICO, "--scene", os.path.join(REPO, "config", "scenes", "liver_phantom.yaml"),
                        "--data", os.path.join(cls.dir.name, "retractor"), "--views", "anterior,superior",
                        "--noise", "0.001", "--quiet", "--csv", rows], check=True)
        with open(rows) as f:
            cls.rows = {r["view"]: {k: (float(v) if k != "view" else v) for k, v in r.items()} for r in csv.DictReader(f)}

    @classmethod
    def tearDownClass(cls):
        cls.dir.cleanup()

    def test_the_supports_hold_what_the_view_does_not_show(self):
        # Targets of issue 49 (mean <= 2 mm, p95 <= 4 mm) on both half views, and the superior
        # view's targets inside their 95% ellipsoids in every depth band. Mutation seen failing:
        # the scene's supports left free (the `support` term of the one-shot's foundation
        # springs zero, run as --set support=0 on the same draw): superior mean 2.00 mm, p95
        # 3.88 mm, 78% inside.
        for view in ("anterior", "superior"):
            r = self.rows[view]
            with self.subTest(view=view):
                self.assertLessEqual(r["tre_mean_mm"], 2.0)
                self.assertLessEqual(r["tre_p95_mm"], 4.0)
                self.assertLess(r["tre_mean_mm"], 0.7 * r["rigid_mean_mm"])
        r = self.rows["superior"]
        self.assertLessEqual(r["tre_mean_mm"], 1.6)
        self.assertLessEqual(r["tre_p95_mm"], 3.2)
        for band in ("all", "middle", "deep"):
            with self.subTest(band=band):
                self.assertGreater(r[band + "_targets"], 100)
                self.assertGreaterEqual(r[band + "_inside_95"], 0.90)


if __name__ == "__main__":
    unittest.main(argv=sys.argv[:1])
