"""``docs/results/evidence.py``: how much of the watch's predicted evidence a user's input gives."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

from sa_daemon.config import load_config
from sa_daemon.sim.users import load_user

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "results" / "evidence.py"
_spec = importlib.util.spec_from_file_location("results_evidence", SCRIPT)
evidence = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(evidence)


def _share(user: str) -> tuple[float, int]:
    cfg = load_user(user).apply(load_config(None))
    rows = evidence.windows(cfg, "scene1", "cup:top", 0, user)
    return sum(r[0] for r in rows) / sum(r[1] for r in rows), len(rows)


def test_a_confident_user_gives_the_evidence_the_watch_predicts_and_a_pausing_one_less():
    """The confident user drives at full deflection toward its goal, the user the watch predicts: the
    realised log-odds move as predicted (slope near 1). The hesitant one pauses: they move less."""
    confident, n_c = _share("confident")
    hesitant, n_h = _share("hesitant")
    assert n_c > 50 and n_h > 50
    assert 0.8 < confident < 1.25
    assert hesitant < 0.8 * confident


def test_the_script_prints_a_slope_per_user_and_pooled(tmp_path):
    out = tmp_path / "e.json"
    run = subprocess.run([sys.executable, str(SCRIPT), "--user", "confident", "--seeds", "1", "--first-seed", "0",
                          "--json", str(out)], capture_output=True, text=True, timeout=600, check=True)
    lines = run.stdout.splitlines()
    assert lines[1].split()[0] == "confident" and lines[-1].split()[0] == "pooled"
    assert out.read_text().count('"lambda"') == 4  # in all, and by move / ho / none
