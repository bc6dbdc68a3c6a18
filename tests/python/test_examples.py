"""The Python examples run and check what they claim (the brute-force example exits non-zero on a mismatch)."""
import os
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
    assert proc.stdout.strip()
    for a in args:
        if a.endswith(".png") and "matplotlib is not installed" not in proc.stdout:
            assert os.path.getsize(a) > 1000
