"""``run_trial(..., pose_known=True)``, the oracle ``docs/results/pose_known.py`` measures with: the
controller's goal for the task holds the user's own grasp pose alone, every other goal keeps its list, and
the seed draws the same user; with the pose known, an own-pose user's trial is faster. And
``docs/results/pose_posterior.py``, which follows the tracker's posterior over the user's pose."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from sa_daemon.config import load_config
from sa_daemon.sim.episode import run_trial
from sa_daemon.sim.users import load_user
from sa_daemon.world.scene import load_scene

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "results" / "pose_known.py"
POSTERIOR = SCRIPT.with_name("pose_posterior.py")
SCENE = load_scene("scene1")
TASK = "cup:top"


def first_goals(user: str, seed: int, known: bool):
    """The goal set of the trial's first plan, and the trial."""
    seen = []
    cfg = load_user(user).apply(load_config(None))
    r = run_trial(SCENE, TASK, "policy", seed, cfg, user_name=user, pose_known=known,
                  on_plan=lambda t, snap, _r: seen.append(snap.goals) if not seen else None)
    return seen[0], r


def test_the_tasks_goal_holds_the_users_own_pose_alone_and_the_others_keep_their_lists():
    listed, _ = first_goals("own-pose-off-list", 300, False)
    known, _ = first_goals("own-pose-off-list", 300, True)
    assert [g.target for g in known.goals] == [g.target for g in listed.goals]
    for a, b in zip(listed.goals, known.goals, strict=True):
        if a.target == TASK:
            assert len(a.poses) > 1 and len(b.poses) == 1
            # off the list: the user's pose is none of the listed ones
            assert min(np.linalg.norm(p.position - b.poses[0].position) for p in a.poses) > 1e-6
        else:
            assert b.poses == a.poses


def test_the_trial_reports_the_pose_its_user_drove_to():
    _, r = first_goals("own-pose-off-list", 300, False)
    known, _ = first_goals("own-pose-off-list", 300, True)
    (pose,) = next(g.poses for g in known.goals if g.target == TASK)
    assert r.user_pose is not None and np.allclose(r.user_pose.position, pose.position)
    assert np.allclose(r.user_pose.quat_wxyz, pose.quat_wxyz)
    assert "user_pose" not in r.metrics()  # not part of the JSON record


def test_knowing_the_pose_shortens_an_own_pose_users_trial():
    _, listed = first_goals("own-pose", 300, False)
    _, known = first_goals("own-pose", 300, True)
    assert listed.success and known.success
    print(f"own-pose, seed 300: {listed.completion_time_s:.1f} s listed, {known.completion_time_s:.1f} s known")
    assert known.completion_time_s < listed.completion_time_s


def test_the_script_prints_the_paired_table(tmp_path):
    out = tmp_path / "pk.json"
    run = subprocess.run([sys.executable, str(SCRIPT), "--scene", "scene1", "--task", TASK, "--user", "own-pose",
                          "--seeds", "1", "--jobs", "1", "--json", str(out)],
                         capture_output=True, text=True, timeout=600, check=True)
    row = [line for line in run.stdout.splitlines() if line.startswith(TASK)]
    assert len(row) == 1 and "own-pose" in row[0]
    spec = importlib.util.spec_from_file_location("results_pose_known", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    trials = json.loads(out.read_text())["trials"]
    assert sorted((t["method"], t["pose_known"]) for t in trials) == [("ho", False), ("ho", True),
                                                                       ("policy", False), ("policy", True)]
    assert set(mod.paired(trials, True)) == {(TASK, "own-pose")}


def test_the_pose_posterior_script_follows_the_users_pose_to_the_close():
    spec = importlib.util.spec_from_file_location("results_pose_posterior", POSTERIOR)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rows, result, lines = mod.posterior_rows("scene1", "chips can:side", "calibrated", 0, "tracked", (1.0,))
    assert lines[0].startswith("t=1.0 s") and 2 <= len(lines) <= 7  # the likeliest poses at 1 s
    assert result.success and rows
    assert all(0.0 <= r[1] <= 1.0 + 1e-9 and r[2] >= 0.0 for r in rows)
    assert rows[-1][3] < rows[0][3]  # the gripper ends nearer the user's pose than it starts
    run = subprocess.run([sys.executable, str(POSTERIOR), "--scene", "scene1", "--task", "chips can:side",
                          "--user", "calibrated", "--seed", "0", "--every", "2"],
                         capture_output=True, text=True, timeout=600, check=True)
    assert run.stdout.splitlines()[0].startswith("t=  0.0 s  user's pose ")
    assert run.stdout.splitlines()[-1].startswith("success at ")
