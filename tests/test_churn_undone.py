"""``docs/results/churn_undone.py``: which trials the yield changed, and when a churn rule asking for undone
switches would fire; and one real trial's switches scored."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"
sys.path.insert(0, str(RESULTS))  # the script imports its neighbour rerun.py
_spec = importlib.util.spec_from_file_location("results_churn_undone", RESULTS / "churn_undone.py")
churn_undone = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(churn_undone)


def test_today_s_rule_fires_at_the_sixth_switch_within_ten_seconds():
    events = [(t, None) for t in (1.0, 2.0, 3.0, 4.0, 5.0, 11.5, 12.0)]
    # 1-5 and 11.5 span 10.5 s; 2-5, 11.5, 12 span 10 s: the rule fires at 12
    assert churn_undone.fires(events, 0) == 12.0
    assert churn_undone.fires(events[:6], 0) is None


def test_a_rule_asking_undone_switches_counts_them_in_the_window():
    # six switches in 5 s; two undone (negative), one undone long before the window, one not undone
    events = [(0.0, -1.0), (20.0, -0.2), (21.0, 0.3), (22.0, None), (23.0, -0.1), (24.0, 0.0), (25.0, 0.5)]
    assert churn_undone.fires(events, 2) == 25.0
    assert churn_undone.fires(events, 3) is None  # the one at 0 s is out of the 10 s window


def test_the_trials_the_yield_changed_are_told_by_outcome(tmp_path):
    def trial(seed, time_s, success, method="policy"):
        return {"scene": "scene1", "task": "cup:top", "user": "own-pose", "method": method, "seed": seed,
                "completion_time_s": time_s, "success": success}
    off = tmp_path / "off.json"
    on = tmp_path / "on.json"
    off.write_text(json.dumps({"trials": [trial(0, 100.0, False), trial(1, 20.0, True), trial(2, 20.0, True),
                                          trial(3, 15.0, True), trial(4, 30.0, True, "blend")]}))
    on.write_text(json.dumps({"trials": [trial(0, 30.0, True), trial(1, 25.0, True), trial(2, 20.0, True),
                                         trial(3, 12.0, True), trial(4, 20.0, True, "blend")]}))
    got = {t["seed"]: t["kind"] for t in churn_undone.changed(off, on, ["policy"])}
    assert got == {0: "mended", 1: "slower", 3: "faster"}  # seed 2 unchanged, seed 4 another method


def test_a_recorded_livelock_rerun_without_the_yield_is_the_recorded_one():
    """The own-pose-off-list user's Table I livelock the yield mends (seed 1711, the policy): run again with
    the yield off it reproduces the time-out recorded before the yield existed (``-pose``), with one scored
    event per recorded mode change; the first switch is not scored (no earlier visit to the mode entered), and
    the rest are, but where the user's last visit to the mode entered had no input."""
    trial = {"src": str(RESULTS / "suite-table1-pop1700-churn.json"), "scene": "scene1", "task": "cup:top",
             "user": "own-pose-off-list", "method": "policy", "seed": 1711}
    (before,) = [t for t in json.loads((RESULTS / "suite-table1-pop1700-pose.json").read_text())["trials"]
                 if all(t[k] == trial[k] for k in ("task", "user", "method", "seed"))]
    recorded = json.loads(Path(trial["src"]).read_text())["meta"]["config"]
    time_s, events = churn_undone.switches(trial, recorded)
    assert time_s == before["completion_time_s"] == 100.0
    assert len(events) == before["mode_changes"] > 40
    assert events[0][1] is None and sum(s is not None for _, s in events) > len(events) / 2
