"""Where the tracker's posterior over the grasp poses of the true target stands, plan by plan, in one trial.

    python docs/results/pose_posterior.py --scene scene1 --task cup:top --user own-pose --seed 300 \\
        [--reach tracked] [--every 1.0] [--at 18 ...]

Runs the trial as ``sa-daemon eval`` does (the policy, kinematic arm, the user's profile over the built-in
defaults, ``intent.reach_pose`` as given; ``tracked`` by default, so the belief keeps each goal's posterior
over its poses) and prints, about every ``--every`` s: the posterior share of the pose the simulated user
wants among all the task target's poses (each goal's probability times its posterior over its own poses;
a pose listed twice, e.g. at two yaws a half-turn apart, counts once per listing), how far the
likeliest pose is from it (cm), how far the gripper is from it (cm), the action chosen, the mode, and
how many resamplings (section III-G: a new goal set) happened since the row before. Under the default
``intent.copy_weights = "poses"`` a resampling starts each copy's posterior over its poses afresh
(``intent.keep_pose_posterior = true`` carries the target's posterior over). The user's pose is the
trial's own (``TrialResult.user_pose``). At
each ``--at`` time (the first plan at or after it) it lists the six likeliest poses: share, offset from
the user's pose (cm, degrees) and from the gripper.
``docs/results.md`` ("Session 42") used it on the own-pose user's Table I trial.
"""

from __future__ import annotations

import argparse

import numpy as np

from sa_daemon.config import config_from_dict
from sa_daemon.geometry import quat_angle
from sa_daemon.sim.episode import run_trial
from sa_daemon.sim.users import load_user
from sa_daemon.world.scene import load_scene

SAME_M = 1e-6
"""Listed poses closer than this (m) to the user's are the user's."""


def posterior_rows(scene_name: str, task: str, user: str, seed: int, reach: str,
                   at: tuple[float, ...] = ()) -> tuple[list[tuple], object, list[str]]:
    """``(t, share of the user's pose, likeliest pose's distance to it (m), gripper's distance to it (m),
    action label, mode, goal set)`` at every plan, the trial's result, and the lines listing the poses at
    the ``at`` times."""
    scene = load_scene(scene_name)
    cfg = load_user(user).apply(config_from_dict({"intent": {"reach_pose": reach}}))
    plans: list[tuple] = []
    result = run_trial(scene, task, "policy", seed, cfg, user_name=user,
                       on_plan=lambda t, snap, res: plans.append((t, snap, res.action.label)))
    want_pose = result.user_pose
    want = want_pose.position
    rows: list[tuple] = []
    lines: list[str] = []
    due = sorted(at)
    for t, snap, label in plans:
        if snap.pose_log_w is None:
            continue
        poses = [(snap.probs[g] * np.exp(snap.pose_log_w[g, k]), p)
                 for g in np.flatnonzero(snap.goals.target_mask(task))
                 for k, p in enumerate(snap.goals.goals[g].poses)]
        total = sum(w for w, _ in poses)
        share = sum(w for w, p in poses if np.linalg.norm(p.position - want) < SAME_M) / total
        likeliest = max(poses, key=lambda wp: wp[0])[1].position
        if due and t + 1e-9 >= due[0]:
            due.pop(0)
            lines.append(f"t={t:.1f} s: the six likeliest of the target's poses")
            for w, p in sorted(poses, key=lambda wp: -wp[0])[:6]:
                lines.append(f"  share {w / total:.2f}  from the user's pose {100 * np.linalg.norm(p.position - want):4.1f} cm "
                             f"{np.degrees(quat_angle(p.quat_wxyz, want_pose.quat_wxyz)):4.0f} deg, from the gripper "
                             f"{100 * np.linalg.norm(p.position - snap.pose.position):4.1f} cm "
                             f"{np.degrees(quat_angle(p.quat_wxyz, snap.pose.quat_wxyz)):4.0f} deg")
        rows.append((t, share, float(np.linalg.norm(likeliest - want)),
                     float(np.linalg.norm(snap.pose.position - want)), label, snap.mode.value, snap.goals))
    return rows, result, lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", required=True)
    ap.add_argument("--task", required=True)
    ap.add_argument("--user", default="own-pose")
    ap.add_argument("--seed", type=int, default=300)
    ap.add_argument("--reach", default="tracked", choices=("tracked", "tracked_moves"))
    ap.add_argument("--every", type=float, default=1.0, help="print a plan about this often (s)")
    ap.add_argument("--at", type=float, action="append", default=[], help="list the likeliest poses here (s)")
    a = ap.parse_args()
    rows, result, lines = posterior_rows(a.scene, a.task, a.user, a.seed, a.reach, tuple(a.at))
    due, resampled, goals = 0.0, 0, rows[0][6] if rows else None
    for t, share, d_likeliest, d_gripper, action, mode, now in rows:
        resampled += now is not goals
        goals = now
        if t + 1e-9 >= due:
            print(f"t={t:5.1f} s  user's pose {share:.2f}  likeliest {100 * d_likeliest:4.1f} cm from it  "
                  f"gripper {100 * d_gripper:5.1f} cm  {action} ({mode})"
                  + (f"  [{resampled} resampling{'s' if resampled > 1 else ''}]" if resampled else ""))
            due, resampled = t + a.every, 0
    print(f"{'success' if result.success else 'failure'} at {result.completion_time_s:.2f} s")
    for line in lines:
        print(line)


if __name__ == "__main__":
    main()
