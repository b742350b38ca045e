"""A simulated joystick user (``docs/simulated-user.md`` describes it completely).

It knows its task and wants one grasp pose of that goal. Like the paper's users it drives one mode at a
time: translate to a pre-grasp point behind the grasp (along the approach axis), switch to rotation and
align the gripper, switch back and translate in. Its command is a saturated proportional twist toward
where it wants to be, computed from the pose it saw ``reaction_delay_s`` ago, plus Gaussian noise: it
naturally fights wrong assistance. It re-plans its mode whenever the assistance disturbs the part it is
not driving. A user whose arm refuses to move on the way to the pre-grasp point (the daemon's safety
pipeline halts it, e.g. at a wrist singularity, and says so) for ``blocked_rotate_s`` rotates the
gripper first, as people do, and then translates on. A mode switch costs ``mode_switch_s`` without input; questions are answered truthfully
(or wrongly with ``answer_error_rate``) after ``answer_delay_s``.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from enum import Enum

import numpy as np

from ..config import InputConfig, SimUserConfig
from ..geometry import FloatArray, Pose, quat_angle, rotation_error
from ..model.actions import Mode
from ..model.twists import axes_to_twist


class Phase(str, Enum):
    APPROACH = "approach"  # translate to the pre-grasp point
    ALIGN = "align"  # rotate to the grasp orientation
    INSERT = "insert"  # translate onto the grasp pose


@dataclass(frozen=True)
class UserInput:
    """One joystick sample: raw ``axes`` in [-1, 1], the ``mode`` they drive, and button intents."""

    axes: FloatArray
    mode: Mode
    close: bool = False

    def twist(self, scale: InputConfig) -> FloatArray:
        """The commanded twist (m/s, rad/s) of these axes in this mode."""
        return axes_to_twist(self.axes, self.mode, scale)


def _saturate(v: FloatArray, limit: float) -> FloatArray:
    n = float(np.linalg.norm(v))
    return v if n <= limit else v * (limit / n)


class SimulatedUser:
    """The user model. Call :meth:`act` once per joystick sample (every ``dt`` s)."""

    def __init__(
        self,
        task: str,
        desired: Pose,
        cfg: SimUserConfig,
        scale: InputConfig,
        rng: np.random.Generator,
        dt: float,
    ) -> None:
        self.task = task
        self.desired = desired
        self.cfg = cfg
        self.scale = scale
        self.rng = rng
        self.dt = dt
        self.mode = Mode.TRANSLATION
        self.phase = Phase.APPROACH
        self.mode_changes = 0
        self._switch_left = 0.0
        self._blocked_s = 0.0  # how long the arm has refused the user's motion (s)
        self._detour = False  # aligning early because the approach was blocked
        self._seen: deque[Pose] = deque(maxlen=round(cfg.reaction_delay_s / dt) + 1)
        # (error, commanded motion this step) over the persistence window.
        self._errors_seen: deque[tuple[float, float]] = deque(maxlen=max(2, round(cfg.persist_window_s / dt)))
        approach = desired.rotation[:, 2]
        self.pregrasp = desired.position - cfg.pregrasp_standoff_m * approach

    # -- perception --------------------------------------------------------------------------------------

    def _errors(self, pose: Pose) -> tuple[FloatArray, float, float]:
        """(translation error to the current target point, its norm, rotation error) as seen."""
        target = self.pregrasp if self.phase is Phase.APPROACH else self.desired.position
        err = target - pose.position
        return err, float(np.linalg.norm(err)), float(quat_angle(self.desired.quat_wxyz, pose.quat_wxyz))

    def at_goal(self, pose: Pose) -> bool:
        """Within the closing tolerance of the desired pose."""
        d_t, d_r = pose.distance(self.desired)
        return d_t <= self.cfg.close_translation_m and d_r <= self.cfg.close_rotation_rad

    # -- decisions ---------------------------------------------------------------------------------------

    def _switch(self, mode: Mode) -> None:
        if mode is not self.mode:
            self.mode = mode
            self.mode_changes += 1
            self._switch_left = self.cfg.mode_switch_s
            self._errors_seen.clear()
            self._blocked_s = 0.0

    def _push(self, err: FloatArray, gain: float, full: float) -> FloatArray:
        """Axes for error ``err``: saturated proportional, or full deflection when stalled."""
        n = float(np.linalg.norm(err))
        hist = self._errors_seen
        commanded = sum(c for _, c in hist)
        stalled = len(hist) == hist.maxlen and hist[0][0] - n < self.cfg.persist_progress * commanded
        axes = err / n if stalled and n > 1e-9 else _saturate(gain * err, full * self.cfg.max_deflection) / full
        hist.append((n, float(np.linalg.norm(axes)) * full * self.dt))
        return axes

    def _update_phase(self, pose: Pose) -> None:
        c = self.cfg
        _, dist, rot = self._errors(pose)
        if self.phase is Phase.APPROACH and dist <= c.pregrasp_tolerance_m:
            self.phase = Phase.ALIGN if rot > c.rotation_done_rad else Phase.INSERT
        elif self.phase is Phase.APPROACH and self._blocked_s >= c.blocked_rotate_s and rot > c.rotation_done_rad:
            self.phase, self._detour = Phase.ALIGN, True  # blocked on the way: turn the gripper first
        elif self.phase is Phase.ALIGN and rot <= c.rotation_done_rad:
            self.phase, self._detour = Phase.INSERT, False
        elif self.phase is Phase.INSERT and rot > c.close_rotation_rad:
            self.phase = Phase.ALIGN  # the assistance turned the gripper away: fix it first
        if self.phase is not Phase.APPROACH and not self._detour:
            # Pushed far off the approach line: back out to the pre-grasp point.
            off = float(np.linalg.norm(pose.position - self.desired.position))
            if off > c.pregrasp_standoff_m + 3 * c.pregrasp_tolerance_m:
                self.phase = Phase.APPROACH
        want = Mode.ROTATION if self.phase is Phase.ALIGN else Mode.TRANSLATION
        self._switch(want)

    def act(self, pose: Pose, listening: bool = False, blocked: bool = False) -> UserInput:
        """The joystick sample for this instant; ``pose`` is the true current pose. While
        ``listening`` to a question the user keeps still; ``blocked`` says the arm refused the last
        command (a joint stage of the safety pipeline halted it, ``SafetyResult.refuses``)."""
        self._blocked_s = self._blocked_s + self.dt if blocked else 0.0
        self._seen.append(pose)
        seen = self._seen[0]  # the oldest kept pose: ``reaction_delay_s`` ago
        if listening:
            return UserInput(np.zeros(3), self.mode)
        if self.at_goal(pose):
            return UserInput(np.zeros(3), self.mode, close=True)
        if self._switch_left > 0.0:
            self._switch_left -= self.dt
            return UserInput(np.zeros(3), self.mode)
        self._update_phase(seen)
        if self._switch_left > 0.0:
            self._switch_left -= self.dt
            return UserInput(np.zeros(3), self.mode)
        c = self.cfg
        if self.mode is Mode.TRANSLATION:
            err, _, _ = self._errors(seen)
            axes = self._push(err, c.linear_gain, self.scale.linear_scale_mps)
        else:
            err = rotation_error(self.desired.quat_wxyz, seen.quat_wxyz)
            axes = self._push(err, c.angular_gain, self.scale.angular_scale_radps)
        if c.noise_std > 0.0:
            axes = axes + self.rng.normal(0.0, c.noise_std, 3)
        return UserInput(np.clip(axes, -1.0, 1.0), self.mode)

    def answer(self, target: str) -> bool:
        """Answer "is ``target`` your goal?" (truthful unless the error rate strikes)."""
        truth = target == self.task
        if self.cfg.answer_error_rate > 0.0 and self.rng.random() < self.cfg.answer_error_rate:
            return not truth
        return truth
