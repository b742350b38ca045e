"""The continued watch (``planner.watch_levels = 2``, ``planner/continued_watch.py``) on real snapshots,
and ``docs/results/watch_level_cost.py``, which prices it.

A child's watch continued for a user heading to ``h`` must be the root's watch run twice as long: for a
move and for no-assist it reaches the pose the root's two-step watch reaches (the rollouts are Markov in
the pose; HO is not compared: its belief restarts from the child's watched belief). The option changes
what watches are worth on Scene 1's bench snapshots and never a commit's or a question's value, and the
script writes its figures. (Its equality with a plain recursion: ``tests/test_watch_model.py``.)
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from sa_daemon.bench.planner import sample_snapshots
from sa_daemon.config import Config
from sa_daemon.model.actions import ActionKind
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.watch import WatchSearch
from sa_daemon.world.scene import load_scene

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "results" / "watch_level_cost.py"
_spec = importlib.util.spec_from_file_location("results_watch_level_cost", SCRIPT)
wlc = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(wlc)

ONE = Config()
TWO = ONE.model_copy(update={"planner": ONE.planner.model_copy(update={"watch_levels": 2})})


@pytest.fixture(scope="module")
def snaps():
    return sample_snapshots(load_scene("scene1"), ONE, 12)


def test_a_continued_watch_reaches_the_two_step_watch_pose(snaps):
    compared = 0
    for snap in snaps[:4]:
        s = WatchSearch(SharedAutonomyModel(TWO), snap)
        R = s.root_rollouts()
        kids = s.start_children(R)
        kids.rollouts.join()
        two = s.rollouts(snap.pose.position[None], snap.pose.quat_wxyz[None], s.b0[None], s.n, 2 * s.n_w)
        for i, (w, h) in enumerate((w, h) for w in s.watched for h in s.branches):
            if s.moves[w].kind is ActionKind.HO:
                continue
            c = kids.of_branch[i]
            assert kids.motions[c] == w
            np.testing.assert_allclose(kids.rollouts.watch_positions[c, h, w], two.watch_positions[0, h, w], atol=1e-9)
            assert abs(abs(float(kids.rollouts.watch_quats[c, h, w] @ two.watch_quats[0, h, w])) - 1.0) < 1e-9
            compared += 1
    assert compared > 0


def test_the_option_changes_watches_only(snaps):
    m1, m2 = SharedAutonomyModel(ONE), SharedAutonomyModel(TWO)
    watches_changed = 0
    for snap in snaps:
        s = WatchSearch(m2, snap)
        a, b = WatchSearch(m1, snap).run(), s.run()
        assert a[0] == b[0]  # the root's commits and questions
        watches_changed += a[1] != b[1]
        assert 0 < s.grandchildren <= s.children * len(s.branches)
    assert watches_changed > 0


def test_the_command_writes_its_figures(tmp_path):
    out = tmp_path / "cost.json"
    assert wlc.main(["--scene", "scene1", "--samples", "3", "--json", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["scene"] == "scene1" and r["snapshots"] == 3
    assert r["grandchildren_p50"] > r["children_p50"] > 0
    assert r["levels_2_ms"]["p50"] > r["levels_1_ms"]["p50"] > 0
    assert 0.0 <= r["plans_changed"] <= 1.0
