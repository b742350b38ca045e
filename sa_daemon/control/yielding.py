"""When the robot yields: the paper's future work (section VI-E.4, VII); off by default but the yield to
mode churn (session 49).

Three free functions of the controller's state, each returning the reason the robot should not assist
now (a ``yielding`` status, ``docs/protocol.md``) or ``None``; the short histories two of them read,
:class:`OppositionWindow` (the user's opposition) and :class:`ModeSwitches` (the user's mode switches);
and :class:`Yielding`, which keeps the histories and asks the rules in order at every control period.
The controller turns moves and HO into no-assistance while it gives a reason.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ..config import BlendConfig
from ..geometry import Pose
from ..model.actions import Mode
from ..model.belief import Belief
from ..world.goals import object_probabilities
from ..world.goalset import GoalSet


class OppositionWindow:
    """Whether the user's input opposed the assistance, for each control period with input over the last
    ``window_s`` seconds (the reward's opposition test, ``reward.opposition_threshold``)."""

    def __init__(self, window_s: float) -> None:
        self._window_s = window_s
        self._periods: deque[tuple[float, bool]] = deque()  # (t s, opposed)

    @property
    def window_s(self) -> float:
        """The history's length, s."""
        return self._window_s

    def add(self, t: float, opposed: bool) -> None:
        """One control period with input at ``t`` (s)."""
        self._periods.append((t, opposed))

    def counts(self, t: float) -> tuple[int, int, float]:
        """``(opposed periods, periods, time they span in s)`` over the window ending at ``t`` (s)."""
        while self._periods and self._periods[0][0] < t - self._window_s:
            self._periods.popleft()
        n = len(self._periods)
        span = self._periods[-1][0] - self._periods[0][0] if n else 0.0
        return sum(o for _, o in self._periods), n, span

    def clear(self) -> None:
        self._periods.clear()


class ModeSwitches:
    """When the user switched joystick mode: the controller shows it the mode at every tick and it notes
    each change, keeping those within the window it is last asked about (the window is the caller's, so a
    person's new settings take effect on the history so far).

    With ``driven`` it notes a change of the mode the user *drives* in instead: a switch counts at the
    first input given in the new mode, and a switch out and back without input between (a glance at the
    other mode) counts nothing (``blend.churn_counts = "driven"``)."""

    def __init__(self, driven: bool = False) -> None:
        self._driven = driven
        self._mode = Mode.TRANSLATION  # the mode last counted in; a task starts in translation
        self._times: deque[float] = deque()  # when the mode changed, s, oldest first

    def see(self, t: float, mode: Mode, driving: bool) -> None:
        """The user's mode at ``t`` (s), and whether they give input in it (``driving``): a change from the
        mode last counted in is a switch (with ``driven``, once they drive in it)."""
        if mode is not self._mode and (driving or not self._driven):
            self._mode = mode
            self._times.append(t)

    def count(self, t: float, window_s: float) -> int:
        """The switches over the ``window_s`` seconds ending at ``t`` (s); older ones are forgotten."""
        while self._times and self._times[0] < t - window_s:
            self._times.popleft()
        return len(self._times)

    def clear(self) -> None:
        self._mode = Mode.TRANSLATION
        self._times.clear()


def user_opposes(window: OppositionWindow, t: float, share: float) -> str | None:
    """``"user_opposes"`` when at least ``share`` of the periods with input over the window (spanning at
    least half of it) opposed the assistance: the user wants a pose of their own."""
    opposed, n, span = window.counts(t)
    return "user_opposes" if span >= 0.5 * window.window_s and opposed >= share * n else None


def mode_churn(history: ModeSwitches, t: float, window_s: float, switches: int) -> str | None:
    """``"mode_churn"`` when the user has switched joystick mode at least ``switches`` times over the last
    ``window_s`` seconds before ``t`` (s): turning, switching to translate, switching back to turn again,
    while the assistance undoes in the mode they left what they did in it (a grasp pose of their own;
    ``docs/model.md``, session 49)."""
    return "mode_churn" if history.count(t, window_s) >= switches else None


def near_object(goals: GoalSet, probs: np.ndarray, pose: Pose, distance_m: float, belief_share: float) -> str | None:
    """``"near_object"`` when the most likely object (its targets' probabilities summed) holds at least
    ``belief_share`` of the belief and one of its grasp poses is within ``distance_m`` (m) of the TCP
    ``pose``: the person fine-tunes alone."""
    obj, held = max(object_probabilities(goals.target_probabilities(probs)).items(), key=lambda kv: kv[1])
    if held < belief_share:
        return None
    nearest = min(float(np.linalg.norm(p.position - pose.position)) for g in goals.goals if g.object == obj for p in g.poses)
    return "near_object" if nearest <= distance_m else None


class Yielding:
    """The yield rules with the histories they read, settings ``blend`` (``blend.opposition_window_s``,
    ``blend.churn_window_s``, ``blend.yield_near_m``; each off at 0). One per controller; a new task starts
    it afresh (:meth:`reset`)."""

    def __init__(self, cfg: BlendConfig) -> None:
        self._cfg = cfg
        self._opposition = OppositionWindow(cfg.opposition_window_s)
        self._switches = ModeSwitches(cfg.churn_counts == "driven")
        self._reason: str | None = None

    @property
    def reason(self) -> str | None:
        """Why the robot yields as of the last :meth:`step` (``"user_opposes"``, ``"mode_churn"``,
        ``"near_object"``), or ``None``."""
        return self._reason

    def step(self, t: float, mode: Mode, has_input: bool, opposed: bool, belief: Belief, pose: Pose) -> str | None:
        """One control period at ``t`` (s): the user's joystick ``mode``, whether they gave input and whether
        it ``opposed`` the assistance (the reward's test), the belief and the TCP ``pose``. Returns (and
        keeps as :attr:`reason`) the first rule's reason, in the order opposition, churn, nearness."""
        self._reason = self._ask(t, mode, has_input, opposed, belief, pose)
        return self._reason

    def _ask(self, t: float, mode: Mode, has_input: bool, opposed: bool, belief: Belief, pose: Pose) -> str | None:
        c = self._cfg
        opposes = churns = None  # both histories see every period, whichever rule yields
        if c.opposition_window_s > 0.0:
            if has_input:
                self._opposition.add(t, opposed)
            opposes = user_opposes(self._opposition, t, c.opposition_share)
        if c.churn_window_s > 0.0:
            self._switches.see(t, mode, has_input)
            churns = mode_churn(self._switches, t, c.churn_window_s, c.churn_switches)
        if opposes or churns:
            return opposes or churns
        if c.yield_near_m > 0.0:
            return near_object(belief.goals, belief.probs, pose, c.yield_near_m, c.yield_near_belief)
        return None

    def reconfigure(self, cfg: BlendConfig) -> None:
        """A person's new settings; the opposition history starts empty if its window changed, the switches'
        if what they count did."""
        if cfg.opposition_window_s != self._opposition.window_s:
            self._opposition = OppositionWindow(cfg.opposition_window_s)
        if cfg.churn_counts != self._cfg.churn_counts:
            self._switches = ModeSwitches(cfg.churn_counts == "driven")
        self._cfg = cfg

    def reset(self) -> None:
        """A new task: no history, no reason."""
        self._opposition.clear()
        self._switches.clear()
        self._reason = None
