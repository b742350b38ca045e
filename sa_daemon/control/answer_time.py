"""How long this person's questions stop the arm, and what the planner charges a question for it.

A question holds the arm still from the moment it is posed until it is answered (``docs/model.md``,
"When to ask"), and the watch model charges that standing still: ``R_d`` at the arm's pose for
``reward.question_time_s``, a whole number of ``planner.rollout_step_s`` steps. The paper gives no time;
2 s is our default, and a person may answer in 1 s or in 4. :class:`AnswerTime` counts the person's
answer times ``t_1 .. t_n`` (s, from the question to the answer) and, with ``asking.learn_answer_time``,
charges the planner

    T_q = dt * max(1, ceil(median(T_0, t_1, .., t_n) / dt))

where ``T_0 = reward.question_time_s`` is the prior counted as one answer and ``dt`` the rollout step:
one slow answer moves the charge halfway (a 4 s answer after the 2 s prior: 3 s), an outlier among
several does not, and a person who answers within one step below the prior (the simulated users' 1.5 s
against 2 s) is charged the prior. A prior of
0 (the commit model's paper reading: a question costs its ``-5`` alone) stays 0. The count goes on
across tasks and starts again when the settings change (a profile switch: another person). On by
default since session 39 (``docs/results.md``, "Session 39").
"""

from __future__ import annotations

import math
import statistics

from ..config import Config


def whole_steps(seconds: float, step_s: float) -> float:
    """``seconds`` rounded up to whole ``step_s`` steps, at least one (s)."""
    return max(1, math.ceil(seconds / step_s - 1e-9)) * step_s


class AnswerTime:
    """One person's answer times (s) and the question time the planner is charged (s)."""

    MIN_SUGGEST = 3
    """Answers before :attr:`suggested_s` says what a profile would set."""

    def __init__(self, cfg: Config) -> None:
        self._times_s: list[float] = []
        self.reconfigure(cfg)

    def reconfigure(self, cfg: Config) -> None:
        """New settings (a profile switch, another person): the count starts again."""
        self._prior_s = cfg.reward.question_time_s
        self._step_s = cfg.planner.rollout_step_s
        self._learn = cfg.asking.learn_answer_time
        self._times_s = []
        self._charged_s = self._prior_s

    def record(self, after_s: float) -> None:
        """An answer ``after_s`` seconds after its question was posed (finite, >= 0; else ignored)."""
        if math.isfinite(after_s) and after_s >= 0.0:
            self._times_s.append(float(after_s))
            if self._learn and self._prior_s > 0.0:
                self._charged_s = whole_steps(statistics.median([self._prior_s, *self._times_s]), self._step_s)

    @property
    def count(self) -> int:
        """Answers counted since the start or the last :meth:`reconfigure`."""
        return len(self._times_s)

    @property
    def median_s(self) -> float | None:
        """The median answer time (s; ``None`` before the first answer)."""
        return statistics.median(self._times_s) if self._times_s else None

    @property
    def charged_s(self) -> float:
        """What the planner charges a question now (s): ``reward.question_time_s``, or with
        ``asking.learn_answer_time`` the module doc's ``T_q`` (kept from the last answer: every snapshot
        reads it)."""
        return self._charged_s

    @property
    def suggested_s(self) -> float | None:
        """From :attr:`MIN_SUGGEST` answers on, the median rounded up to whole rollout steps: what this
        person's profile would set as ``reward.question_time_s`` (s; ``None`` before)."""
        median = self.median_s
        return whole_steps(median, self._step_s) if median is not None and self.count >= self.MIN_SUGGEST else None

    def summary(self) -> dict[str, float | int | bool | None]:
        """``status``'s ``answer_times`` (``docs/protocol.md``): ``count`` answers since the start or the
        last profile switch, their ``median_s`` (s, from the question to the answer), ``charged_s`` (what the
        planner charges now), ``learning`` (``asking.learn_answer_time``) and ``suggested_s`` (from three
        answers on, what a profile would set, ``docs/profiles.md``, "A slow answerer"); ``None`` where there
        is nothing to say."""
        median, suggested = self.median_s, self.suggested_s
        return {"count": self.count, "median_s": None if median is None else round(median, 3),
                "charged_s": round(self.charged_s, 6), "learning": self._learn,
                "suggested_s": None if suggested is None else round(suggested, 6)}
