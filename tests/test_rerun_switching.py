"""``docs/results/rerun_switching.py``: a recorded evaluation again with the yield to mode churn, rerunning
only the trials with enough mode switches for it to act; the others are kept as recorded."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from sa_daemon.config import config_from_dict
from sa_daemon.sim.evaluate import (
    TrialSpec,
    compare,
    run_trials,
    summarise,
    write_results,
)

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "results" / "rerun_switching.py"


def test_the_script_reruns_the_churning_trials_and_keeps_the_rest(tmp_path):
    cfg = config_from_dict({"blend": {"churn_window_s": 0.0}})  # recorded as before session 49
    specs = [TrialSpec("scene1", "cup:top", "ho", 1711, "own-pose-off-list"),  # the livelock: a time-out
             TrialSpec("scene1", "cup:top", "ho", 0, "calibrated"),
             TrialSpec("scene1", "cup:top", "manual", 0, "calibrated")]
    trials = run_trials(specs, cfg, jobs=1, progress=False)
    assert not trials[0]["success"] and trials[0]["mode_changes"] >= 30
    assert trials[1]["mode_changes"] < 6
    src, dst = tmp_path / "src.json", tmp_path / "dst.json"
    meta = {"scene": "scene1", "tasks": ["cup:top"], "methods": ["ho", "manual"], "seeds": 1, "arm": "kinematic",
            "config": cfg.model_dump(mode="json")}
    write_results(src, trials, summarise(trials), meta, compare(trials))
    out = subprocess.run([sys.executable, str(SCRIPT), str(src), str(dst), "--jobs", "1"],
                         capture_output=True, text=True, timeout=600, check=True)
    assert "1 of 3 trials rerun" in out.stderr
    new = json.loads(dst.read_text())
    assert new["meta"]["rerun_switching"]["trials"] == [["scene1", "cup:top", "own-pose-off-list", "ho", 1711]]
    assert new["meta"]["config"]["blend"]["churn_window_s"] == 10.0
    freed, kept, manual = new["trials"]
    assert freed["success"] and freed["mode_changes"] <= 12
    assert kept == trials[1] and manual == trials[2]
    rows = {(r["user"], r["method"]): r for r in new["summary"]}
    assert rows[("own-pose-off-list", "ho")]["success_rate"] == 1.0
