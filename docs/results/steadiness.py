"""How often the arm's assistance changes its mind: the applied action's changes and the robot's
translation reversals per second, over the eight simulated users.

    python docs/results/steadiness.py --scene scene1 --task cup:top --seeds 5 [--first-seed 300] \\
        [--config A.toml --config B.toml ...]

For each configuration (the built-in defaults where none is given) it runs the policy's trials as
``sa-daemon eval`` does (kinematic arm, every user, seeds ``first-seed ..``) with their timelines and
prints, over all of them: the applied action's changes per second of task (a move to another goal or
grasp pose, HO, no-assist, a question: the label the controller applies, tick by tick), the robot
twist's translation reversals per second (consecutive control periods whose robot translations, both
above 1 mm/s, point more than 90 degrees apart) and the mean completion time. The paper's reason for
HO at the start ("Different move-to-goal actions are selected ... could confuse the user", section
IV-A.3) is the first figure's concern. ``docs/results.md`` ("Session 42") used it.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from sa_daemon.config import load_config
from sa_daemon.sim.episode import run_trial
from sa_daemon.sim.users import builtin_user_names, load_user
from sa_daemon.world.scene import load_scene

MOVING_MPS = 1e-3
"""A robot translation slower than this (m/s) has no direction to reverse."""


def measure(job: tuple[str, str, str, int, str | None]) -> tuple[float, int, int]:
    """One trial's completion time (s), applied-action changes and robot translation reversals."""
    scene, task, user, seed, config = job
    cfg = load_user(user).apply(load_config(config))
    tl = run_trial(load_scene(scene), task, "policy", seed, cfg, record=True, user_name=user).timeline
    changes = sum(a != b for a, b in zip(tl.action, tl.action[1:]))
    v = np.array(tl.robot_twist)[:, :3]
    speed = np.linalg.norm(v, axis=1)
    moving = (speed[1:] > MOVING_MPS) & (speed[:-1] > MOVING_MPS)
    reversed_ = np.sum(v[1:] * v[:-1], axis=1) < 0.0
    return tl.t[-1] - tl.t[0], changes, int(np.sum(moving & reversed_))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", required=True)
    ap.add_argument("--task", required=True)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--first-seed", type=int, default=300)
    ap.add_argument("--config", action="append", default=None, help="config.toml; repeat to compare")
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    for config in a.config or [None]:
        jobs = [(a.scene, a.task, u, a.first_seed + s, config) for u in builtin_user_names()
                for s in range(a.seeds)]
        with ProcessPoolExecutor(a.jobs) as pool:
            rows = list(pool.map(measure, jobs))
        total = sum(r[0] for r in rows)
        print(f"{config or 'defaults'}: {len(rows)} trials, action changes {sum(r[1] for r in rows) / total:.2f}/s, "
              f"translation reversals {sum(r[2] for r in rows) / total:.3f}/s, mean time {total / len(rows):.2f} s")


if __name__ == "__main__":
    main()
