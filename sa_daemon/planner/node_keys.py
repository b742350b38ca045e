"""Keys that tell the watch search's nodes apart, so that equal nodes are searched once.

A question node's belief depends on its start pose and the *set* of answers given, not their order
(:func:`answer_keys`); a watched child depends on its pose and belief alone (:func:`distinct_rows`).
"""

from __future__ import annotations

import numpy as np

from ..geometry import FloatArray


def answer_keys(start: np.ndarray, asked: np.ndarray, yes: np.ndarray) -> np.ndarray:
    """One key per node from its start pose and its answer sets: a 1-D ``int64`` (start, asked bits,
    yes bits) when they fit in 62 bits, else rows of bytes. Equal keys, equal beliefs."""
    nq = asked.shape[1]
    planes = [asked, yes] if yes.dtype == bool else [asked, yes == 1, yes == 2]  # third answer: 2 = "other"
    if len(planes) * nq + int(start.max(initial=0)).bit_length() <= 62:
        weights = np.left_shift(np.int64(1), np.arange(nq, dtype=np.int64))
        key = start.astype(np.int64)
        for plane in planes:
            key = (key << nq) | (plane.astype(np.int64) @ weights)
        return key
    return np.concatenate((start[:, None].astype(np.int64).view(np.uint8).reshape(len(start), -1),
                           *(np.packbits(plane, axis=1) for plane in planes)), axis=1)


def distinct_rows(rows: FloatArray) -> tuple[np.ndarray, np.ndarray]:
    """The first row of each distinct value of ``rows`` ``(n, m)`` in order of appearance, and for every
    row the index of its value among them (``np.unique(..., axis=0)``'s index and inverse, unsorted: a
    dictionary of the rows' bytes, ten times faster on a plan's few dozen rows). ``+ 0.0`` makes ``-0.0``
    and ``0.0`` the same bytes, as they are the same number."""
    seen: dict[bytes, int] = {}
    first: list[int] = []
    kid = np.empty(len(rows), dtype=int)
    for i, row in enumerate(np.ascontiguousarray(rows + 0.0)):
        k = seen.setdefault(row.tobytes(), len(first))
        if k == len(first):
            first.append(i)
        kid[i] = k
    return np.array(first, dtype=int), kid
