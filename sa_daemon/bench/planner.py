"""``sa-daemon bench planner``: solve times, anytime agreement, the pomdp_py peer, belief update cost.

Snapshots are sampled along simulated approaches in the scene: one trial per high-level target with
the ``ho`` and the ``policy`` methods, every planning step recorded, then evenly thinned to
``samples``. Each snapshot is solved

* to the proven optimum (no budget): ``solve_ms_p50`` / ``solve_ms_p99``;
* at ``budget_s`` wall-clock: ``agreement_at_budget`` is the fraction whose action is optimal (its exact
  value equals the optimum: ties count as agreement);
* by pomdp_py's POUCT on the same model with the same budget: ``peer_agreement_at_budget``. For the watch
  model the peer plans the snapshot's :class:`~..planner.watch_tree.WatchTree`, written down by an
  exhaustive search before its clock starts (``bench/peer.py``).

``belief_update_us_p50`` times one joystick update of the belief (MaxEnt IOC + resampling check) for
the scene's goals, and ``belief_update_us_p50_22goals`` for 22 goals, the paper's complex scene.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from ..config import Config
from ..extras import require
from ..geometry import Pose
from ..model.belief import Belief
from ..model.model import SharedAutonomyModel
from ..planner.kernel import supported
from ..planner.problem import Problem
from ..planner.snapshot import Snapshot
from ..planner.solver import Solver
from ..planner.split import threads
from ..planner.watch import WatchSearch
from ..sim.episode import run_trial
from ..world.scene import Scene


def sample_snapshots(scene: Scene, cfg: Config, samples: int) -> list[Snapshot]:
    """Planner inputs met along simulated approaches to every target of ``scene``."""
    snaps: list[Snapshot] = []
    for task in scene.targets:
        for method in ("ho", "policy"):
            run_trial(scene, task, method, 0, cfg, on_plan=lambda _t, s, _r: snaps.append(s))
    idx = np.linspace(0, len(snaps) - 1, min(samples, len(snaps))).round().astype(int)
    return [dataclasses.replace(snaps[i], method="policy") for i in idx]


def _time_updates(model: SharedAutonomyModel, belief: Belief, pose: Pose, n: int = 400) -> float:
    u = np.array([0.1, -0.05, 0.02, 0.0, 0.0, 0.0])
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        model.update_input(belief, pose, u)
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e6)


def belief_update_costs(scene: Scene, model: SharedAutonomyModel) -> tuple[float, float]:
    """Median update time (us) for the scene's goals and for 22 goals (scene goals repeated)."""
    b = model.initial_belief(scene.goals)
    goals22 = tuple(scene.goals[i % len(scene.goals)] for i in range(22))
    return _time_updates(model, b, scene.start), _time_updates(model, model.initial_belief(goals22), scene.start)


def run_planner_bench(
    scene: Scene, cfg: Config, samples: int = 200, budget_s: float = 0.1, peer: bool = True
) -> dict:
    """Run the benchmark and return its figures (see module doc)."""
    model = SharedAutonomyModel(cfg)
    solver = Solver(model)
    if peer:
        require("pomdp_py", "bench")  # one line naming the extra, not a traceback
        from .peer import pouct_plan, pouct_plan_watch
    snaps = sample_snapshots(scene, cfg, samples)
    solve_ms, agree, peer_agree, questions, complete = [], 0, 0, 0, 0
    for i, snap in enumerate(snaps):
        full = solver.plan(dataclasses.replace(snap, budget_s=None, node_budget=None))
        solve_ms.append(full.time_ms)
        complete += full.complete
        questions += full.is_question
        timed = solver.plan(dataclasses.replace(snap, budget_s=budget_s, node_budget=None))
        # every root action's exact value: the watch model's unbudgeted plan holds them, the commit model's
        # bounds may have pruned some, so it asks the solver (untimed either way)
        values = full.root_values if cfg.planner.model == "watch" else None
        if timed.action == full.action or timed.value >= full.value - 1e-9:
            agree += 1
        else:
            values = values or solver.action_values(snap)
            agree += values[timed.action] >= full.value - 1e-9
        if peer:
            if cfg.planner.model == "watch":
                tree = WatchSearch(model, snap).tree()  # exhaustive: tree() runs to the end
                act = pouct_plan_watch(tree, budget_s, seed=i)
            else:
                act = pouct_plan(Problem(model, snap), budget_s, seed=i)
            if act != full.action:
                values = values or solver.action_values(snap)
                peer_agree += values[act] >= full.value - 1e-9
            else:
                peer_agree += 1
    upd, upd22 = belief_update_costs(scene, model)
    n = len(snaps)
    return {
        "scene": scene.name,
        "goals": len(scene.goals),
        "samples": n,
        "budget_s": budget_s,
        "model": cfg.planner.model,
        "top_goals": cfg.planner.top_goals,
        "max_questions": cfg.planner.max_questions,
        "lookahead_steps": cfg.reward.lookahead_steps,
        "rollouts": (f"compiled, {threads(cfg)} thread(s)" if supported(cfg) else "numpy")
        if cfg.planner.model == "watch" else None,
        "solve_ms_p50": float(np.percentile(solve_ms, 50)),
        "solve_ms_p90": float(np.percentile(solve_ms, 90)),
        "solve_ms_p99": float(np.percentile(solve_ms, 99)),
        "solve_ms_max": float(np.max(solve_ms)),
        "proven_fraction": complete / n,
        "question_fraction": questions / n,
        "agreement_at_budget": agree / n,
        "peer": "pomdp_py POUCT" if peer else None,
        "peer_agreement_at_budget": peer_agree / n if peer else None,
        "belief_update_us_p50": upd,
        "belief_update_us_p50_22goals": upd22,
    }


def format_table(r: dict) -> str:
    """Human-readable summary with the issue's targets."""
    peer = r["peer_agreement_at_budget"]
    rows = [
        ("solve to proven optimum, p50", f"{r['solve_ms_p50']:.2f} ms", "<= 10 ms"),
        ("solve to proven optimum, p99", f"{r['solve_ms_p99']:.2f} ms", "<= 100 ms"),
        ("solve, max", f"{r['solve_ms_max']:.2f} ms", ""),
        (f"agreement at {r['budget_s']:.2f} s", f"{r['agreement_at_budget']:.3f}", ">= 0.99, > peer"),
        ("peer (pomdp_py POUCT) agreement", "-" if peer is None else f"{peer:.3f}", ""),
        ("belief update, p50", f"{r['belief_update_us_p50']:.0f} us", ""),
        ("belief update, 22 goals, p50", f"{r['belief_update_us_p50_22goals']:.0f} us", "<= 200 us"),
        ("decisions that are questions", f"{r['question_fraction']:.3f}", ""),
    ]
    w = max(len(a) for a, _, _ in rows)
    head = (f"planner benchmark: {r['scene']} ({r['goals']} goals, {r['samples']} snapshots, G_m={r['top_goals']}, "
            f"{r.get('model', 'commit')} model" + (f", {r['rollouts']} rollouts" if r.get("rollouts") else "") + ")")
    return "\n".join([head] + [f"  {a:<{w}}  {b:>12}  {c}" for a, b, c in rows])


def write_json(r: dict, path: str | Path) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(json.dumps(r, indent=2) + "\n")
