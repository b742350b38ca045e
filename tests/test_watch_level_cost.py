"""``docs/results/watch_level_cost.py``: the price of a second watch level, measured on the right tree.

The script times grandchildren built from the children's own rollouts. That they are the continued
watch is checked here: for a move and for no-assist, the child's watch continued for a user heading to
``h`` reaches the pose the root's two-step watch reaches (the rollouts are Markov in the pose; HO is not
compared: its belief restarts from the child's watched belief). The counts are one grandchild per
(child, branch), and the command writes its figures.
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

CFG = Config()
MODEL = SharedAutonomyModel(CFG)


@pytest.fixture(scope="module")
def snaps():
    return sample_snapshots(load_scene("scene1"), CFG, 4)


def test_a_continued_watch_reaches_the_two_step_watch_pose(snaps):
    compared = 0
    for snap in snaps:
        s = WatchSearch(MODEL, snap)
        R = s.root_rollouts()
        g, ws = s.branches, s.watched
        pos = np.concatenate([R.watch_positions[0, g, w] for w in ws])
        quat = np.concatenate([R.watch_quats[0, g, w] for w in ws])
        kids = s.rollouts(pos, quat, s.child_beliefs(R, ws), s.n - s.n_w, s.n_w)
        two = s.rollouts(snap.pose.position[None], snap.pose.quat_wxyz[None], s.b0[None], s.n, 2 * s.n_w)
        for i, w in enumerate(ws):
            if s.moves[w].kind is ActionKind.HO:
                continue
            for j, h in enumerate(g):
                c = i * len(g) + j
                np.testing.assert_allclose(kids.watch_positions[c, h, w], two.watch_positions[0, h, w], atol=1e-9)
                assert abs(abs(float(kids.watch_quats[c, h, w] @ two.watch_quats[0, h, w])) - 1.0) < 1e-9
                compared += 1
    assert compared > 0


def test_one_grandchild_per_child_and_branch(snaps):
    for snap in snaps[:2]:
        s = WatchSearch(MODEL, snap)
        r = wlc.second_level_cost(s)
        assert r["children"] == len(s.watched) * len(s.branches)
        assert r["grandchildren"] == r["children"] * len(s.branches)
        assert r["today_s"] > 0 and r["children_s"] > 0 and r["grandchildren_s"] > 0


def test_the_command_writes_its_figures(tmp_path):
    out = tmp_path / "cost.json"
    assert wlc.main(["--scene", "scene1", "--samples", "3", "--json", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["scene"] == "scene1" and r["snapshots"] >= 1
    assert r["grandchildren_p50"] > r["children_p50"] > 0
    assert r["with_second_level_ms"]["p50"] > r["today_ms"]["p50"]
