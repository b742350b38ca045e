"""``docs/results/trace.py``: the planner's choice taken apart agrees with the planner, and the script runs."""

from __future__ import annotations

import dataclasses
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

from sa_daemon.config import load_config
from sa_daemon.model.actions import ActionKind
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.watch import plan_watch
from sa_daemon.sim.episode import run_trial
from sa_daemon.world.scene import load_scene

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "results" / "trace.py"
_spec = importlib.util.spec_from_file_location("results_trace", SCRIPT)
trace_script = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(trace_script)


def test_every_action_is_worth_the_better_of_its_commit_and_its_watch():
    cfg = load_config(None)
    model = SharedAutonomyModel(cfg)
    snaps = []
    run_trial(load_scene("scene1"), "cup:top", "policy", 0, cfg,
              on_plan=lambda t, snap, _r: snaps.append(snap) if t in (0.0, 1.0, 2.0) else None)
    assert len(snaps) == 3
    watched = 0
    for snap in snaps:
        exact = plan_watch(model, dataclasses.replace(snap, budget_s=None, node_budget=None))
        parts = trace_script.search_parts(model, snap)
        assert parts["complete"]
        assert 0.0 < sum(p for _, p in parts["branches"]) <= 1.0 + 1e-9
        assert len(parts["stay"]) == len(parts["branches"])
        for action, value in exact.root_values.items():
            if action.kind is ActionKind.QUESTION:
                continue
            best = max(parts["commit"][action][0], parts["watch"].get(action, -float("inf")))
            assert value == pytest.approx(best, rel=1e-9, abs=1e-9), action.label
            watched += action in parts["watch"]
    assert watched > 0


def test_the_script_prints_the_plans_and_opens_the_search():
    out = subprocess.run(
        [sys.executable, str(SCRIPT), "--scene", "scene1", "--task", "cup:top", "--seed", "0", "--to", "0.3",
         "--at", "0.2"], capture_output=True, text=True, timeout=300, check=True).stdout.splitlines()
    times = [float(m.group(1)) for line in out if (m := re.match(r"t=\s*([0-9.]+) ", line))]
    assert times == pytest.approx([0.0, 0.1, 0.2, 0.3])
    assert any(line.startswith("search at t=0.20") for line in out)
    assert any(line.strip().startswith("commit ho") for line in out)
    assert any(line.strip().startswith("watch  none") for line in out)
    assert out[-1].startswith(("success at", "failure:"))
