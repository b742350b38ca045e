"""``docs/results/evidence.py``: how much of the watch's predicted evidence a user's input gives."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "results" / "evidence.py"
_spec = importlib.util.spec_from_file_location("results_evidence", SCRIPT)
evidence = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(evidence)


def test_a_confident_user_gives_the_evidence_the_watch_predicts_and_a_pausing_one_less():
    """The confident user drives at full deflection toward its goal, the user the watch predicts: over the
    four tasks the realised log-odds move about as predicted (slope near 1). The hesitant one pauses:
    they move less. One trial alone is too noisy to say either (its slope ranges 0.2-0.9)."""
    confident = evidence.measure("confident", range(1))
    hesitant = evidence.measure("hesitant", range(1))
    assert confident["windows"] > 100 and hesitant["windows"] > 100
    assert 0.7 < confident["lambda"] < 1.4
    assert hesitant["lambda"] < 0.75 * confident["lambda"]


def test_the_script_prints_a_slope_per_user_and_pooled(tmp_path):
    out = tmp_path / "e.json"
    run = subprocess.run([sys.executable, str(SCRIPT), "--user", "confident", "--seeds", "1", "--first-seed", "0",
                          "--json", str(out)], capture_output=True, text=True, timeout=600, check=True)
    lines = run.stdout.splitlines()
    assert lines[1].split()[0] == "confident" and lines[-1].split()[0] == "pooled"
    assert out.read_text().count('"lambda"') == 6  # in all, by move / ho / none, by translation / rotation


def test_the_windows_split_by_mode_add_up_to_all_of_them():
    """Each window counts once, in the mode of its start: the two modes' sums are the whole's."""
    m = evidence.measure("calibrated", range(1))
    assert m["translation"]["windows"] + m["rotation"]["windows"] == m["windows"]
    assert m["translation"]["windows"] > 0 and m["rotation"]["windows"] > 0
    assert (m["translation"]["predicted_sq"] + m["rotation"]["predicted_sq"]
            == pytest.approx(m["predicted_sq"], rel=1e-9))
