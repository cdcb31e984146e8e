#!/usr/bin/python3
"""The launch files as users run them, without a master: liver_sim.launch passes every parameter
the node reads (found in the node's sources) from a launch argument of the same name, and
playback.launch keeps the node and rviz when the bag ends (the player is not required).

usage: test/launch_check.py PACKAGE_DIR   (ctest runs it)
"""
import glob
import os
import re
import sys
import unittest
import xml.etree.ElementTree as ET

PACKAGE = sys.argv.pop(1) if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..")


def node_parameters():
    """Private parameters the node reads: ~name in param("name") / getParam("name") calls."""
    names = set()
    for path in glob.glob(os.path.join(PACKAGE, "src", "node", "*.cpp")):
        with open(path) as source:
            names |= set(re.findall(r'\b(?:param|getParam)(?:<[^>]*>)?\(\s*"([a-z_]+)"', source.read()))
    return names


class LaunchFiles(unittest.TestCase):
    def test_every_node_parameter_has_a_launch_argument(self):
        launch = ET.parse(os.path.join(PACKAGE, "launch", "liver_sim.launch")).getroot()
        args = {a.get("name") for a in launch.iter("arg")}
        node = next(n for n in launch.iter("node") if n.get("type") == "liver_sim_node")
        passed = {}
        for p in node.iter("param"):
            passed[p.get("name")] = p.get("value")
        for p in node.iter("rosparam"):
            passed[p.get("param")] = p.text
        wanted = node_parameters()
        self.assertGreaterEqual(len(wanted), 10)  # the pattern still finds the node's parameters
        for name in sorted(wanted):
            self.assertIn(name, passed, f"~{name} is not set by liver_sim.launch")
            self.assertEqual(passed[name].strip(), f"$(arg {name})", f"~{name} does not come from its own argument")
            self.assertIn(name, args)
        for name, value in passed.items():
            for used in re.findall(r"\$\(arg ([a-z_]+)\)", value or ""):
                self.assertIn(used, args, f"~{name} uses the undeclared argument {used}")

    def test_playback_keeps_the_node_when_the_bag_ends(self):
        launch = ET.parse(os.path.join(PACKAGE, "launch", "playback.launch")).getroot()
        player = next(n for n in launch.iter("node") if n.get("name") == "player")
        self.assertNotEqual(player.get("required", "false").lower(), "true")
        self.assertTrue(any(i.get("file", "").endswith("liver_sim.launch") for i in launch.iter("include")))


if __name__ == "__main__":
    unittest.main()
