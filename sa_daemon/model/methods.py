"""The assistance methods compared in the paper, selectable by name everywhere; defined here only
(this module imports nothing of the package, so ``config.py`` reads it).

``policy`` and its ablations plan over the POMDP's high-level actions; the baselines follow fixed rules:

==========================  ===========================================================================
``manual``                  no assistance: the user's twist alone
``ho``                      hindsight optimisation toward the belief (Javdani et al.), blended
``ho+noassist``             HO, but the user's twist alone whenever HO opposes it (section IV)
``blend``                   predict-then-act: move to the most likely goal when ``p1 - p2 > margin``
``policy``                  POMDP over move-to-goal, HO, no-assist and question actions
``policy+noqns``            ... without questions
``policy+withoutnoassist``  ... without the no-assist action
``policy+noho``             ... without the HO action
==========================  ===========================================================================
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MethodSpec:
    """Which actions a method may take and whether it plans."""

    name: str
    planned: bool
    moves: bool = False
    ho: bool = False
    noassist: bool = False
    questions: bool = False


_SPECS = {
    "manual": MethodSpec("manual", planned=False, noassist=True),
    "ho": MethodSpec("ho", planned=False, ho=True),
    "ho+noassist": MethodSpec("ho+noassist", planned=False, ho=True, noassist=True),
    "blend": MethodSpec("blend", planned=False, moves=True, noassist=True),
    "policy": MethodSpec("policy", planned=True, moves=True, ho=True, noassist=True, questions=True),
    "policy+noqns": MethodSpec("policy+noqns", planned=True, moves=True, ho=True, noassist=True),
    "policy+withoutnoassist": MethodSpec("policy+withoutnoassist", planned=True, moves=True, ho=True, questions=True),
    "policy+noho": MethodSpec("policy+noho", planned=True, moves=True, noassist=True, questions=True),
}
METHODS = tuple(_SPECS)
"""Every method's name, in the paper's order: the one list (config validation and the CLI read it)."""


def method_spec(name: str) -> MethodSpec:
    """The spec of method ``name``; ``ValueError`` listing the methods if unknown."""
    try:
        return _SPECS[name]
    except KeyError:
        raise ValueError(f"unknown method {name!r} (one of {', '.join(METHODS)})") from None
