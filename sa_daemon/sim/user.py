"""A simulated joystick user (``docs/simulated-user.md`` describes it completely).

It knows its task and wants one grasp pose of that goal. Like the paper's users it drives one mode at a
time: translate to a pre-grasp point behind the grasp (along the approach axis), switch to rotation and
align the gripper, switch back and translate in (or, ``order = "rotate_first"``, align first). Its command
is a saturated proportional twist toward where it wants to be, computed from the pose it saw
``reaction_delay_s`` ago, plus Gaussian noise (and, per profile, tremor, bursts, one axis at a time): it
naturally fights wrong assistance. It re-plans its mode whenever the assistance disturbs the part it is
not driving. A user whose arm refuses to move on the way to the pre-grasp point (the safety pipeline
halts it, e.g. at a wrist singularity, and says so) for ``blocked_rotate_s`` rotates the gripper first,
as people do, and then translates on. A mode switch costs ``mode_switch_s`` without input; questions are
answered truthfully (or wrongly with ``answer_error_rate``) after ``answer_delay_s`` (or a uniform delay
up to ``answer_delay_max_s``).

Randomness comes from the ``rng`` given; the behaviours a profile switches on draw from it only when on,
so the calibrated user's draws (and numbers) do not depend on them.
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
from ..world.goals import target_object


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
        self._t = 0.0  # time since the first sample (s)
        self._pause_left = cfg.start_pause_s
        self._mid_pause_due = cfg.mid_pause_s > 0.0
        self._start_dist: float | None = None
        self._answer_delays: dict[int, float] = {}
        self._close_m = cfg.close_translation_m
        if cfg.close_translation_max_m is not None:  # this trial's closing tolerance
            self._close_m = float(rng.uniform(cfg.close_translation_m, cfg.close_translation_max_m))
        self._tremor_phase = rng.uniform(0.0, 2.0 * np.pi, 3) if cfg.tremor_std > 0.0 else np.zeros(3)
        if cfg.order == "rotate_first":
            self.phase, self._detour = Phase.ALIGN, True  # turn the gripper at the start, then translate
            self.mode = Mode.ROTATION

    # -- perception --------------------------------------------------------------------------------------

    def _errors(self, pose: Pose) -> tuple[FloatArray, float, float]:
        """(translation error to the current target point, its norm, rotation error) as seen."""
        target = self.pregrasp if self.phase is Phase.APPROACH else self.desired.position
        err = target - pose.position
        return err, float(np.linalg.norm(err)), float(quat_angle(self.desired.quat_wxyz, pose.quat_wxyz))

    def at_goal(self, pose: Pose) -> bool:
        """Within this user's closing tolerance of the desired pose (it closes the gripper there)."""
        d_t, d_r = pose.distance(self.desired)
        return d_t <= self._close_m and d_r <= self.cfg.close_rotation_rad

    @property
    def close_translation_m(self) -> float:
        """This trial's closing tolerance (m): ``close_translation_m``, or drawn up to
        ``close_translation_max_m``."""
        return self._close_m

    def answer_delay(self, qid: int) -> float:
        """How long this user takes to answer question ``qid`` (s), drawn once per question."""
        c = self.cfg
        if c.answer_delay_max_s is None:
            return c.answer_delay_s
        if qid not in self._answer_delays:
            self._answer_delays[qid] = float(self.rng.uniform(c.answer_delay_s, c.answer_delay_max_s))
        return self._answer_delays[qid]

    def answers_by(self, qid: int, asked_at: float, t: float) -> bool:
        """Whether this user has answered question ``qid``, asked at ``asked_at`` (s), by time ``t`` (s):
        the evaluation and the daemon's simulated input both ask this (1 ns tolerance for float steps)."""
        return t - asked_at >= self.answer_delay(qid) - 1e-9

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
        if self.cfg.one_axis:  # one axis at a time: the one with the largest error
            k = int(np.argmax(np.abs(axes)))
            axes = np.where(np.arange(3) == k, axes, 0.0) * (np.linalg.norm(axes) / max(abs(axes[k]), 1e-12))
            axes = np.clip(axes, -1.0, 1.0)
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
        t, self._t = self._t, self._t + self.dt
        self._blocked_s = self._blocked_s + self.dt if blocked else 0.0
        self._seen.append(pose)
        seen = self._seen[0]  # the oldest kept pose: ``reaction_delay_s`` ago
        if listening:
            return self._still()
        if self.at_goal(pose):
            return UserInput(np.zeros(3), self.mode, close=True)
        if self._pause_left > 1e-9 or self._mid_pause(seen):  # hesitating: hands off the stick
            self._pause_left -= self.dt
            return self._still()
        if self._switch_left > 0.0:
            self._switch_left -= self.dt
            return self._still()
        self._update_phase(seen)
        self._corrective_switch()
        if self._switch_left > 0.0:
            self._switch_left -= self.dt
            return self._still()
        c = self.cfg
        if c.burst_s > 0.0 and (t % (c.burst_s + c.burst_pause_s)) >= c.burst_s:
            return self._still()  # between two bursts the stick is released
        if self.mode is Mode.TRANSLATION:
            err, _, _ = self._errors(seen)
            axes = self._push(err, c.linear_gain, self.scale.linear_scale_mps)
        else:
            err = rotation_error(self.desired.quat_wxyz, seen.quat_wxyz)
            axes = self._push(err, c.angular_gain, self.scale.angular_scale_radps)
        if c.noise_std > 0.0:
            axes = axes + self.rng.normal(0.0, c.noise_std, 3)
        if c.tremor_std > 0.0:  # an oscillation of the hand on the stick, std tremor_std per axis
            axes = axes + c.tremor_std * np.sqrt(2.0) * np.sin(2.0 * np.pi * c.tremor_hz * t + self._tremor_phase)
        return UserInput(np.clip(axes, -1.0, 1.0), self.mode)

    def _still(self) -> UserInput:
        """Hands off the stick, in the current mode."""
        return UserInput(np.zeros(3), self.mode)

    def _mid_pause(self, seen: Pose) -> bool:
        """Start the one pause halfway to the pre-grasp point (``mid_pause_s``), if it is due."""
        if not self._mid_pause_due or self.phase is not Phase.APPROACH:
            return False
        dist = float(np.linalg.norm(self.pregrasp - seen.position))
        if self._start_dist is None:
            self._start_dist = dist
        if dist > 0.5 * self._start_dist:
            return False
        self._mid_pause_due = False
        self._pause_left = self.cfg.mid_pause_s
        return True

    def _corrective_switch(self) -> None:
        """Now and then (``corrective_switch_hz``) switch to the other mode to check it; the next decision
        switches back. Two counted switches, each costing ``mode_switch_s``."""
        rate = self.cfg.corrective_switch_hz
        if rate > 0.0 and self._switch_left <= 0.0 and self.rng.random() < rate * self.dt:
            self._switch(Mode.ROTATION if self.mode is Mode.TRANSLATION else Mode.TRANSLATION)

    def answer(self, target: str, third: bool = False) -> bool | str:
        """Answer "is ``target`` your goal?" (truthful unless the error rate strikes): ``True``/``False``,
        or with ``third`` (``asking.third_answer``) ``"other"`` when ``target`` is the right object with the
        wrong grasp type."""
        truth = target == self.task
        if self.cfg.answer_error_rate > 0.0 and self.rng.random() < self.cfg.answer_error_rate:
            return not truth
        if third and not truth and target_object(target) == target_object(str(self.task)):
            return "other"
        return truth
