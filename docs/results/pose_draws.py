"""Which grasp pose a simulated user drew in each recorded trial, and what the trials did, split by the draw.

    python docs/results/pose_draws.py docs/results/suite-*-pop1700-pose.json [--user own-pose] [--turn 30]

The scenes list every grasp pose twice, at two yaws half a turn apart about the tool's approach axis
(``docs/scenes.md``: the same grasp for the parallel gripper, the arm reaching each differently). A user
whose ``sim_user.pose_choice`` draws among the listed poses (``own-pose``: any listed pose but ``k_c``)
may draw the listing that needs the longer turn from the start. This script draws each trial's pose
again as ``run_trial`` does (same seed, same reachable scene, ``sim/episode.py``'s ``desired_pose``) and
calls a draw *turned around* when a listing of the same grasp point needs at least ``--turn`` degrees
less turn from the start. Per task and kind of draw it prints the seeds, the extra turn (deg, mean),
each method's mean time over its successes (s), the policy's time over HO's on the seeds both succeed
on (ratio of means), and the policy's questions a task, trials above 3 questions and correct prediction.
``docs/results.md`` ("Session 46") used it on the own-pose user.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from functools import cache

import numpy as np

from sa_daemon.arm.reach import reachable_scene
from sa_daemon.config import Config
from sa_daemon.geometry import quat_angle
from sa_daemon.sim.episode import desired_pose, kinematic_arm
from sa_daemon.sim.success import scene_object
from sa_daemon.sim.users import load_user
from sa_daemon.world.goalset import SAME_POINT_M
from sa_daemon.world.scene import Scene, load_scene


@cache
def reachable(scene_name: str, user: str) -> tuple[Scene, Config]:
    """The scene as ``run_trial`` sees it on the kinematic arm, and the user's configuration."""
    cfg = load_user(user).apply(Config())
    scene = load_scene(scene_name)
    arm = kinematic_arm(scene, cfg)
    if arm.kinematics is not None:
        scene = reachable_scene(scene, arm.kinematics, cfg.safety.joint_margin_rad)
    arm.close()
    return scene, cfg


def extra_turn_deg(scene_name: str, task: str, seed: int, user: str) -> float:
    """How much further (deg) the drawn pose is turned from the start than its grasp point's least-turned
    listing."""
    scene, cfg = reachable(scene_name, user)
    goal = scene.goal(task)
    want = desired_pose(goal, scene.start, cfg, np.random.default_rng(seed), None, scene_object(scene, goal.object))

    def turn(quat_wxyz: np.ndarray) -> float:
        return float(np.degrees(quat_angle(quat_wxyz, scene.start.quat_wxyz)))

    same = [p for p in goal.poses if np.linalg.norm(p.position - want.position) <= SAME_POINT_M]
    return turn(want.quat_wxyz) - min(turn(p.quat_wxyz) for p in same)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+", help="suite files (docs/results/*.json)")
    ap.add_argument("--user", default="own-pose")
    ap.add_argument("--turn", type=float, default=30.0, help="a draw this much (deg) past its twin is turned around")
    a = ap.parse_args()
    trials: dict[tuple[str, str], dict[int, dict[str, dict]]] = defaultdict(lambda: defaultdict(dict))
    for path in a.files:
        with open(path) as f:
            for x in json.load(f)["trials"]:
                if x["user"] == a.user:
                    trials[(x["scene"], x["task"])][x["seed"]][x["method"]] = x
    methods = sorted({m for by_seed in trials.values() for ms in by_seed.values() for m in ms})
    print(f"| task | draw | seeds | extra turn (deg) | {' | '.join(f'{m} s' for m in methods)} | policy / HO "
          "| questions | trials > 3 questions | correct prediction |")
    print("|---|---|---|---|" + "---|" * len(methods) + "---|---|---|---|")
    for (scene_name, task), by_seed in sorted(trials.items()):
        extra = {s: extra_turn_deg(scene_name, task, s, a.user) for s in by_seed}
        for turned in (False, True):
            seeds = [s for s in sorted(by_seed) if (extra[s] >= a.turn) == turned]
            if not seeds:
                continue
            times = []
            for m in methods:
                ok = [by_seed[s][m]["completion_time_s"] for s in seeds if m in by_seed[s] and by_seed[s][m]["success"]]
                times.append(f"{np.mean(ok):.1f}" if ok else "-")
            pol = [by_seed[s]["policy"] for s in seeds if "policy" in by_seed[s]]
            pairs = [(by_seed[s]["policy"]["completion_time_s"], by_seed[s]["ho"]["completion_time_s"]) for s in seeds
                     if {"policy", "ho"} <= by_seed[s].keys() and by_seed[s]["policy"]["success"]
                     and by_seed[s]["ho"]["success"]]
            ratio = f"{np.mean([p for p, _ in pairs]) / np.mean([h for _, h in pairs]):.2f}" if pairs else "-"
            q = [x["questions"] for x in pol]
            print(f"| {scene_name} `{task}` | {'turned around' if turned else 'other'} | {len(seeds)} "
                  f"| {np.mean([extra[s] for s in seeds]):.0f} | {' | '.join(times)} | {ratio} "
                  f"| {np.mean(q):.2f} | {sum(v > 3 for v in q)} | {np.mean([x['correct_prediction'] for x in pol]):.2f} |")


if __name__ == "__main__":
    main()
