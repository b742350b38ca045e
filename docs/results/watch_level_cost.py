"""What a second watch level costs the search and what it changes: ``planner.watch_levels`` 1 against 2.

With ``planner.watch_levels = 2`` a child of a watched motion may keep it for another watch before it
asks or commits (``planner/continued_watch.py``; ``docs/model.md``, "A watch that may be continued").
It costs one grandchild per (child, branch), each with its own rollouts and decision. For every
snapshot ``bench planner`` samples in the scene this solves the plan to the end with both settings
(no budget, as ``bench planner``'s proven-optimum figures) and reports the solve times (median and 99th
percentile, ms, wall-clock on this machine), the children and grandchildren searched, and how many
plans choose another action.

Usage: ``python docs/results/watch_level_cost.py --scene study-complex --samples 200 [--json OUT]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json

import numpy as np

from sa_daemon.bench.planner import sample_snapshots
from sa_daemon.config import Config
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.watch import WatchSearch, plan_watch
from sa_daemon.world.scene import load_scene


def run(scene_name: str, samples: int) -> dict:
    """The figures of the module doc over ``samples`` of the scene's bench snapshots."""
    one = Config()
    two = one.model_copy(update={"planner": one.planner.model_copy(update={"watch_levels": 2})})
    m1, m2 = SharedAutonomyModel(one), SharedAutonomyModel(two)
    t1, t2, kids, grand, changed = [], [], [], [], 0
    snaps = [dataclasses.replace(s, budget_s=None, node_budget=None) for s in sample_snapshots(
        load_scene(scene_name), one, samples)]
    for snap in snaps:
        a, b = plan_watch(m1, snap), plan_watch(m2, snap)
        t1.append(a.time_ms)
        t2.append(b.time_ms)
        changed += a.action != b.action
        search = WatchSearch(m2, snap)
        search.run()
        kids.append(search.children)
        grand.append(search.grandchildren)

    def ms(a: list[float]) -> dict[str, float]:
        return {"p50": float(np.median(a)), "p99": float(np.percentile(a, 99))}

    return {"scene": scene_name, "snapshots": len(snaps), "levels_1_ms": ms(t1), "levels_2_ms": ms(t2),
            "children_p50": float(np.median(kids)), "grandchildren_p50": float(np.median(grand)),
            "grandchildren_max": int(max(grand)), "plans_changed": changed / len(snaps)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="scene1")
    ap.add_argument("--samples", type=int, default=100)
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args(argv)
    r = run(args.scene, args.samples)
    print(f"{r['scene']}: {r['snapshots']} snapshots; children {r['children_p50']:.0f}, grandchildren "
          f"{r['grandchildren_p50']:.0f} (p50, at most {r['grandchildren_max']}); plans changed {r['plans_changed']:.2f}")
    for key in ("levels_1_ms", "levels_2_ms"):
        print(f"  watch_{key[:8]:<10} solve p50 {r[key]['p50']:7.2f} ms   p99 {r[key]['p99']:7.2f} ms")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(r, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
