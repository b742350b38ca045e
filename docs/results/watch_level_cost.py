"""What a second watch level would cost the search: a watch that may be continued, priced before building it.

Today's watch model (``docs/model.md``, "When to ask") lets the root watch a motion for ``planner.watch_s``
and then ask or commit; the daemon re-plans every 0.1 s and may keep watching, which the model does not
credit. An exact second level gives each child (motion ``w``, branch ``g``) the choice to watch ``w``
again, and the tracker's choice there is judged by its belief over every branch ``h``: one grandchild per
(child, branch), with its own rollouts over ``n - 2 n_w`` steps and its own decision (questions included).

For every snapshot ``bench planner`` samples, this times, with the product's own pieces:

* today's whole search (root, root questions, children and their decisions);
* the children's rollouts again, with the watch step a second level needs (``loglik`` from the child);
* the grandchildren: their beliefs (the children's watched update, :func:`watched_beliefs`), their
  rollouts, and the tracker's decision at each (:meth:`WatchSearch.decide`).

Usage: ``python docs/results/watch_level_cost.py --scene study-complex --samples 100 [--json OUT]``.
Times are wall-clock on this machine (median and 99th percentile, ms).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from sa_daemon.bench.planner import sample_snapshots
from sa_daemon.config import Config
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.watch import WatchSearch
from sa_daemon.planner.watched_beliefs import watched_beliefs
from sa_daemon.world.scene import load_scene


def second_level_cost(search: WatchSearch) -> dict[str, float]:
    """Time (s) and size of one snapshot's search today and of the second level it would add."""
    t0 = time.perf_counter()
    R = search.root_rollouts()
    asked = np.zeros((1, len(search.questions)), dtype=bool)
    kids = search.start_children(R)
    search._root_questions(R, asked)
    search.watch_values(R, kids, asked)
    t1 = time.perf_counter()
    g, ws = search.branches, search.watched
    pos = np.concatenate([R.watch_positions[0, g, w] for w in ws])
    quat = np.concatenate([R.watch_quats[0, g, w] for w in ws])
    B = search.child_beliefs(R, ws)
    n, n_w = search.n, search.n_w
    K = search.rollouts(pos, quat, B, n - n_w, n_w)  # every child, with the step a continued watch reads
    t2 = time.perf_counter()
    share, copy = search.cfg.planner.watch_evidence, search.cfg.planner.watch_copy_evidence
    target_index = search.snap.goals.target_index
    gp, gq, gb = [], [], []
    for i, w in enumerate(ws):
        for j in range(len(g)):
            c = i * len(g) + j  # child of (motion w, branch g[j]); its watch of w continued, user heading to h
            gp.append(K.watch_positions[c, g, w])
            gq.append(K.watch_quats[c, g, w])
            gb.append(watched_beliefs(B[c], K.loglik[c][g, w], target_index, share, copy))
    gp, gq, gb = np.concatenate(gp), np.concatenate(gq), np.concatenate(gb)
    G2 = search.rollouts(gp, gq, gb, n - 2 * n_w)
    m = len(gb)
    none = np.zeros((m, len(search.questions)), dtype=bool)
    search.decide(G2, np.arange(m), gb, none, none.copy(), n - 2 * n_w)
    t3 = time.perf_counter()
    return {"today_s": t1 - t0, "children_s": t2 - t1, "grandchildren_s": t3 - t2,
            "children": float(len(B)), "grandchildren": float(m)}


def run(scene_name: str, samples: int) -> dict:
    """The figures of the module doc over ``samples`` of the scene's bench snapshots."""
    cfg = Config()
    model = SharedAutonomyModel(cfg)
    rows = []
    for snap in sample_snapshots(load_scene(scene_name), cfg, samples):
        search = WatchSearch(model, snap)
        if search.watched and search.n > 2 * search.n_w:
            rows.append(second_level_cost(search))

    def ms(key: str) -> dict[str, float]:
        a = np.array([r[key] for r in rows]) * 1e3
        return {"p50": float(np.median(a)), "p99": float(np.percentile(a, 99))}

    today = np.array([r["today_s"] for r in rows])
    added = np.array([r["children_s"] + r["grandchildren_s"] for r in rows])
    return {
        "scene": scene_name, "snapshots": len(rows),
        "today_ms": ms("today_s"), "children_with_watch_ms": ms("children_s"), "grandchildren_ms": ms("grandchildren_s"),
        "with_second_level_ms": {"p50": float(np.median(today + added) * 1e3),
                                 "p99": float(np.percentile(today + added, 99) * 1e3)},
        "children_p50": float(np.median([r["children"] for r in rows])),
        "grandchildren_p50": float(np.median([r["grandchildren"] for r in rows])),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="scene1")
    ap.add_argument("--samples", type=int, default=100)
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args(argv)
    r = run(args.scene, args.samples)
    print(f"{r['scene']}: {r['snapshots']} snapshots; children {r['children_p50']:.0f}, "
          f"grandchildren {r['grandchildren_p50']:.0f} (p50)")
    for key in ("today_ms", "children_with_watch_ms", "grandchildren_ms", "with_second_level_ms"):
        print(f"  {key:<24} p50 {r[key]['p50']:7.2f} ms   p99 {r[key]['p99']:7.2f} ms")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(r, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
