"""The paper's per-trial measures (section IV), as pure functions of a recorded trajectory.

A trajectory is sampled at the joystick rate (0.025 s in the paper): raw 3-axis input, the mode it drove,
and whether the robot's twist opposed the user's (section III-E rule) at that sample.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import pairwise

import numpy as np

PREDICTION_THRESHOLD = 0.7


def joystick_input(axes: Sequence[Sequence[float]]) -> float:
    """Total joystick input: the sum of the absolute raw input of the 3 axes over all samples."""
    a = np.asarray(axes, dtype=float).reshape(-1, 3)
    return float(np.abs(a).sum())


def opposing_pct(opposed: Sequence[bool]) -> float:
    """Percentage of samples where the robot's action opposed the user's."""
    o = np.asarray(opposed, dtype=bool)
    return 100.0 * float(o.mean()) if o.size else 0.0


def mode_changes(modes: Sequence[str]) -> int:
    """Number of switches between translation and rotation mode."""
    return int(sum(a != b for a, b in pairwise(modes)))


def correct_prediction(final_target_p: float, threshold: float = PREDICTION_THRESHOLD) -> bool:
    """The true high-level target has probability above ``threshold`` (0.7) at the end."""
    return bool(final_target_p > threshold)
