"""``docs/results/steadiness.py`` and ``planner.switch_margin`` in closed loop: holding the adopted motion
on near ties makes the applied action change less often, and the script prints its figures."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "results" / "steadiness.py"
_spec = importlib.util.spec_from_file_location("results_steadiness", SCRIPT)
steadiness = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(steadiness)

CASES = [("calibrated", 300), ("hasty", 300), ("own-pose", 300)]


def test_a_switch_margin_makes_the_applied_action_change_less_often(tmp_path):
    held = tmp_path / "held.toml"
    held.write_text("[planner]\nswitch_margin = 50.0\n")
    free = [steadiness.measure(("scene1", "cup:top", u, s, None)) for u, s in CASES]
    steady = [steadiness.measure(("scene1", "cup:top", u, s, str(held))) for u, s in CASES]
    rate = [sum(r[1] for r in rows) / sum(r[0] for r in rows) for rows in (free, steady)]
    print(f"applied-action changes a second: {rate[0]:.2f} free, {rate[1]:.2f} held")
    assert rate[1] < 0.8 * rate[0], rate
    assert all(r[0] > 0 and r[1] >= 0 and r[2] >= 0 for r in free + steady)


def test_the_script_prints_one_row_a_configuration(tmp_path):
    out = subprocess.run([sys.executable, str(SCRIPT), "--scene", "scene1", "--task", "chips can:side",
                          "--seeds", "1", "--jobs", "1"], capture_output=True, text=True, timeout=600, check=True)
    assert out.stdout.startswith("defaults: 8 trials, action changes ") and "mean time" in out.stdout
