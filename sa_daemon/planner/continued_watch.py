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
(child, branch) with its own rollouts: affordable on Scene 1, about five times the whole search on 18-22
goals (``docs/results/watch_level_cost.py``; ``docs/model.md``, "A watch that may be continued").

Pure functions of arrays: :func:`grandchildren` where each child's continued watch leads,
:func:`continued_vectors` what it is worth from the grandchildren's decisions; the search
(:meth:`~.watch.WatchSearch.decide`) rolls the grandchildren out and decides them in between.
"""

from __future__ import annotations

import numpy as np

from ..geometry import FloatArray
from .rollouts import Rollouts
from .watched_beliefs import watched_beliefs


def _continuing(n: int, branches: np.ndarray, motions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Index arrays ``(n, 1)``, ``(1, nb)``, ``(n, 1)`` picking, for every child and branch ``h``, the
    child's own motion and ``h``."""
    return np.arange(n)[:, None], branches[None, :], motions[:, None]


def grandchildren(kids: Rollouts, beliefs: FloatArray, motions: np.ndarray, branches: np.ndarray,
                  target_index: np.ndarray, evidence: float, copy_evidence: float
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Where each child's watch continued leads, child by child and branch ``h`` by branch: the positions
    ``(n nb, 3)`` (m) and orientations ``(n nb, 4)`` (``quat_wxyz``) its motion reaches in the children's
    watched steps ``kids`` while a user heading to ``h`` drives, and the child's belief ``beliefs[c]``
    updated with that input's evidence (:func:`watched_beliefs`, the shares ``evidence`` and
    ``copy_evidence``). ``motions`` ``(n,)``: each child's motion, an action index of ``kids``."""
    n, G = beliefs.shape
    c, h, w = _continuing(n, branches, motions)
    nb = len(branches)
    ll = kids.loglik[c, h, w].reshape(n * nb, G)
    after = watched_beliefs(np.repeat(beliefs, nb, axis=0), ll, target_index, evidence, copy_evidence)
    return kids.watch_positions[c, h, w].reshape(n * nb, 3), kids.watch_quats[c, h, w].reshape(n * nb, 4), after


def continued_vectors(kids: Rollouts, beliefs: FloatArray, motions: np.ndarray, branches: np.ndarray,
                      decided: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``cont_c`` of the module doc for every child: the vectors ``(n, G)`` and the values the tracker
    weighs them by ``(n,)``, from what each grandchild's decision earns for each goal, ``decided``
    ``(n nb, G)`` in :func:`grandchildren`'s order."""
    n, G = beliefs.shape
    c, h, w = _continuing(n, branches, motions)
    ret = kids.watch_return[c, h, w] + decided[np.arange(n * len(branches)), np.tile(branches, n)].reshape(n, -1)
    weights = beliefs[:, branches]  # each branch its own goal's return, weighed by b' over the branches
    value = (weights * ret).sum(axis=1) / np.maximum(weights.sum(axis=1), 1e-300)
    vectors = np.repeat(value[:, None], G, axis=1)
    vectors[:, branches] = ret
    return vectors, value
