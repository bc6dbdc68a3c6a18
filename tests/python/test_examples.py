"""The Python examples run and check what they claim (the brute-force example exits non-zero on a mismatch)."""
import os
import re
import subprocess
import sys

import pytest

from conftest import ROOT

EXAMPLES = ROOT / "examples" / "python"


@pytest.mark.parametrize("script, args", [
    ("brute_force_check.py", ["--rays", "1500"]),
    ("picking_moving_scene.py", ["--steps", "3"]),
    ("rays_from_numpy.py", ["--size", "64", "--out", "{tmp}/depth.png"]),
    ("sensor_sweep.py", ["--rays", "20000", "--angles", "10,40", "--out", "{tmp}/sweep.png"]),
])
def test_example_runs(tmp_path, script, args):
    args = [a.format(tmp=tmp_path) for a in args]
    proc = subprocess.run([sys.executable, str(EXAMPLES / script), *args], capture_output=True, text=True,
                          env=dict(os.environ), timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = proc.stdout
    if script == "picking_moving_scene.py":
        steps = [line for line in out.splitlines() if line.startswith("joint_1 at")]
        assert len(steps) == 3, out
        # Turning the joint moves the robot's links beyond it (8 instances), every step after the first.
        assert all(" 8 instances moved" in line for line in steps[1:]), out
    elif script == "rays_from_numpy.py":
        hit, total = re.search(r"(\d+) of (\d+) rays hit", out).groups()
        assert total == str(64 * 64) and 0 < int(hit) < int(total), out
    elif script == "sensor_sweep.py":
        assert len(re.findall(r"half angle .* W", out)) == 2, out
    for a in args:
        if a.endswith(".png") and "matplotlib is not installed" not in proc.stdout:
            assert os.path.getsize(a) > 1000
