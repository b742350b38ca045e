"""The paper's experiments as named suites: ``sa-daemon eval --suite NAME`` runs one across the users.

A suite is data: the scenes, tasks and methods of one experiment, and the paper's own figures for it
(questions per task where the paper reports them), printed beside ours.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..model.methods import METHODS


@dataclass(frozen=True)
class SuitePart:
    """Tasks of one scene, each run with every method."""

    scene: str
    tasks: tuple[str, ...]
    methods: tuple[str, ...]


@dataclass(frozen=True)
class Suite:
    name: str
    summary: str
    parts: tuple[SuitePart, ...]
    paper_questions: dict[str, float] | None = None
    """Questions per task the paper's policy asked (task -> mean), where it reports them."""
    seeds: int = 10
    """Seeds per cell by default: enough for a paired test over ``6 x (methods - 1)`` Holm-corrected
    comparisons per (task, user) to reach p < 0.05 (the smallest exact two-sided Wilcoxon p over n
    pairs is ``2 / 2^n``)."""


_FIG7 = ("ho", "ho+noassist", "policy")
_STUDY = ("manual", "ho", "policy")

SUITES: dict[str, Suite] = {
    s.name: s
    for s in (
        Suite("table1", "Table I: Scene 1 cup:top, all eight methods",
              (SuitePart("scene1", ("cup:top",), tuple(METHODS)),), seeds=20),
        Suite("fig7", "Fig. 7 / Table III: the eight simulation tasks, HO, HO+NoAssist and policy",
              (SuitePart("scene1", ("cup:top", "chips can:side", "bowl:top", "cup:side"), _FIG7),
               SuitePart("scene2", ("cup:top_horizontal", "scissors:side_vertical", "drill:side_vertical",
                                    "spoon:top_vertical"), _FIG7))),
        Suite("study-simple", "section V: the simple user study's three tasks, manual, HO and policy",
              (SuitePart("study-simple", ("bottle:side", "spoon:top", "cup:top"), _STUDY),),
              {"bottle:side": 0.41, "spoon:top": 1.12, "cup:top": 1.24}),
        Suite("study-complex", "section VI: the 22-goal scene's three tasks, manual, HO and policy",
              (SuitePart("study-complex", ("bowl:top_horizontal", "can:side_horizontal", "drill:side_vertical"),
                         _STUDY),),
              {"bowl:top_horizontal": 0.4, "can:side_horizontal": 0.8, "drill:side_vertical": 0.92}),
    )
}


def suite(name: str) -> Suite:
    """The suite called ``name``; ``KeyError`` naming the suites there are."""
    if name not in SUITES:
        raise KeyError(f"no suite {name!r} (suites: {', '.join(SUITES)})")
    return SUITES[name]
