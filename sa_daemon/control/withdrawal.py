"""Answers the person's opposition can withdraw (``asking.withdraw_yes_s``, ``asking.withdraw_no_s``).

Answers are final in our reading of the paper (``docs/model.md``, "A yes is final"); a misheard or
mistaken one then holds the arm on the wrong target, or away from the person's, while they fight it.
:class:`AnswerWithdrawal` keeps one :class:`~.yielding.OppositionWindow` for a standing "yes" and one for
standing "no" answers, and withdraws the answer once the person has opposed the assistance in
``blend.opposition_share`` of the control periods with input over its window.
"""

from __future__ import annotations

from ..config import Config
from ..model.belief import Belief
from .yielding import OppositionWindow, user_opposes


class AnswerWithdrawal:
    """The opposition since the last answer, and how many answers this task were withdrawn."""

    def __init__(self, cfg: Config) -> None:
        self._cfg = cfg
        self._yes = OppositionWindow(cfg.asking.withdraw_yes_s)  # while a "yes" holds
        self._no = OppositionWindow(cfg.asking.withdraw_no_s)  # while "no" answers hold and no "yes" does
        self._yes_withdrawn = 0
        self._no_withdrawn = 0

    @property
    def yes_withdrawn(self) -> int:
        """"Yes" answers withdrawn this task."""
        return self._yes_withdrawn

    @property
    def no_withdrawn(self) -> int:
        """Times this task the "no" answers were withdrawn."""
        return self._no_withdrawn

    def reconfigure(self, cfg: Config) -> None:
        """New settings; a window whose length changed starts empty."""
        self._cfg = cfg
        if cfg.asking.withdraw_yes_s != self._yes.window_s:
            self._yes = OppositionWindow(cfg.asking.withdraw_yes_s)
        if cfg.asking.withdraw_no_s != self._no.window_s:
            self._no = OppositionWindow(cfg.asking.withdraw_no_s)

    def answered(self) -> None:
        """A new answer: the opposition counts from now."""
        self._yes.clear()
        self._no.clear()

    def reset(self) -> None:
        """A new task or scene: empty windows, nothing withdrawn."""
        self.answered()
        self._yes_withdrawn = 0
        self._no_withdrawn = 0

    def step(self, belief: Belief, t: float, assisting: bool, opposed: bool) -> Belief | None:
        """One control period at ``t`` (s): ``assisting`` whether the person gave input while the arm
        assisted (a move or HO), ``opposed`` whether that input opposed it (the reward's test). While a
        "yes" holds (else while a "no" does) the period is counted in that answer's window; returns the
        belief with the answer withdrawn (:meth:`~..model.belief.Belief.without_confirmation`, or
        :meth:`~..model.belief.Belief.without_denials`) once the window says so, else ``None``."""
        a, yes = self._cfg.asking, belief.confirmed is not None
        if yes:
            window, seconds = self._yes, a.withdraw_yes_s
        elif belief.ruled_out:
            window, seconds = self._no, a.withdraw_no_s
        else:
            return None
        if seconds <= 0.0:
            return None
        if assisting:
            window.add(t, opposed)
        if not user_opposes(window, t, self._cfg.blend.opposition_share):
            return None
        window.clear()
        if yes:
            self._yes_withdrawn += 1
            return belief.without_confirmation()
        self._no_withdrawn += 1
        return belief.without_denials()
