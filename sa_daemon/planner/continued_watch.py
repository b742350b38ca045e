"""A watch continued once (``planner.watch_levels = 2``): a child of a watched motion may keep it.

The daemon plans again every ``planner.period_s`` and may go on watching; with one watch level the model
makes every child of a watch ask or commit. With two, the child ``c`` reached by motion ``w`` (pose
``x'``, belief ``b'``, ``s' = n - n_w`` steps left) may also run ``w`` for another ``n_w`` steps while a
user heading to each branch ``h`` drives, the belief updated by the same watched evidence
(:func:`~.watched_beliefs.watched_beliefs`), and then decide (ask or commit; no third watch):

    cont_c[h] = W_x'[h, w] + D(b''_ch, x''_ch, s' - n_w)[h]         for every branch h

The tracker at ``c`` weighs it by ``b'`` renormalised over the branches (``planner.watch_branches``
"top" or "all"), as the root weighs a watch, against its commits and questions by ``b'``; the vector a
chosen continuation gives a goal outside the branches is that weighted value (the root's "top"
convention). So the root's watch of ``w`` is worth, for goal ``g``, ``W_x[g, w] + D_2(b'_gw, x'_gw, s')[g]``
with ``D_2`` choosing among commits, questions and the continued watch. It costs one grandchild per
(child, branch) with its own rollouts: affordable on Scene 1, five to ten times the whole search on 18-22
goals (``docs/results/watch_level_cost.py``; ``docs/model.md``, "A watch that may be continued").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..geometry import FloatArray
from .node_keys import distinct_rows
from .watched_beliefs import watched_beliefs

if TYPE_CHECKING:
    from .rollouts import Rollouts
    from .watch import WatchSearch


def continued(search: WatchSearch, kids: Rollouts, beliefs: FloatArray, motions: np.ndarray,
              asked: np.ndarray) -> tuple[FloatArray, FloatArray]:
    """``cont_c`` of the module doc for every child ``c`` of ``kids`` (rollouts run with ``n_w`` watched
    steps; beliefs ``(n, G)``, each child's motion ``motions`` ``(n,)``, questions ``asked`` ``(n, Q)``):
    the vectors ``(n, G)`` and the values the tracker weighs them by ``(n,)``."""
    n, G = beliefs.shape
    g = search.branches
    c, h, w = np.arange(n)[:, None], g[None, :], motions[:, None]  # (n, 1), (1, nb), (n, 1)
    nb = len(g)
    pos = kids.watch_positions[c, h, w].reshape(n * nb, 3)
    quat = kids.watch_quats[c, h, w].reshape(n * nb, 4)
    ll = kids.loglik[c, h, w].reshape(n * nb, G)
    share, copy = search.watch_share()
    B2 = watched_beliefs(np.repeat(beliefs, nb, axis=0), ll, search.snap.goals.target_index, share, copy)
    first, kid = distinct_rows(np.concatenate((pos, quat, B2), axis=1))
    search.grandchildren = len(first)
    steps = search.n - 2 * search.n_w
    grand = search.rollouts(pos[first], quat[first], B2[first], steps)
    A = np.repeat(asked[:1], len(first), axis=0)
    V2, _ = search.decide(grand, np.arange(len(first)), B2[first], A, A.copy(), steps)
    ret = kids.watch_return[c, h, w] + V2[kid, np.tile(g, n)].reshape(n, nb)  # each branch's own goal
    weights = beliefs[:, g]
    value = (weights * ret).sum(axis=1) / np.maximum(weights.sum(axis=1), 1e-300)
    vectors = np.repeat(value[:, None], G, axis=1)
    vectors[:, g] = ret
    return vectors, value
