"""The beliefs the watch search expects: Bayes' rule on answers and on predicted joystick input.

Pure functions of arrays (no model, no search): :func:`posterior` is the tracker's update by a
log-likelihood, :func:`watched_beliefs` the tempered update a watched branch expects
(``planner.watch_evidence``, ``planner.watch_copy_evidence``; ``docs/model.md``).
"""

from __future__ import annotations

import numpy as np

from ..geometry import FloatArray


def posterior(b0: FloatArray, ll: FloatArray) -> FloatArray:
    """Bayes: ``b0 * exp(ll)`` normalised per row of ``ll`` ``(m, G)``, ``b0`` one prior ``(G,)`` or one a row
    ``(m, G)``; goals ``b0`` rules out stay out."""
    log_b = np.log(np.maximum(b0, 1e-300)) + ll
    log_b -= log_b.max(axis=1, keepdims=True)
    b = np.exp(log_b) * (b0 > 0)
    return b / b.sum(axis=1, keepdims=True)


def watched_beliefs(b0: FloatArray, ll: FloatArray, target_index: np.ndarray, evidence: float = 1.0,
                    copy_evidence: float = 1.0) -> FloatArray:
    """The beliefs the watch expects after predicted input of log-likelihood ``ll`` ``(m, G)`` (nats, one
    row a branch) from belief ``b0`` (``(G,)``, or one a row ``(m, G)``). With ``lambda = evidence``
    (``planner.watch_evidence``) and
    ``kappa = copy_evidence`` (``planner.watch_copy_evidence``), for goal ``g`` of target ``t(g)``:

        P(t)     = sum over g' in t of  b0[g'] exp(lambda ll[g'])  /  sum over all g' of the same
        b'[g]    = P(t(g)) * b0[g] exp(kappa lambda ll[g])  /  sum over g' in t(g) of the same

    so each target's mass is Bayes' rule on the input's tempered evidence, and the copies of a target
    (resampled grasp poses, III-G) part by ``kappa`` of it: ``kappa = 1`` is Bayes' rule over the goals,
    ``kappa = 0`` keeps ``b0``'s split among the copies."""
    ll = evidence * ll
    b = posterior(b0, ll)
    if copy_evidence == 1.0 or len(np.unique(target_index)) == len(target_index):
        return b
    onehot = target_index[:, None] == np.arange(int(target_index.max()) + 1)[None, :]  # (G, T)
    mass = b @ onehot  # (m, T)
    w = posterior(b0, copy_evidence * ll)
    within = w @ onehot
    return mass[:, target_index] * np.divide(w, within[:, target_index], out=np.zeros_like(w),
                                             where=within[:, target_index] > 0)
