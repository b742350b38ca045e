"""The same POMDP for pomdp_py's POUCT: the peer our solver is compared against (``bench planner``).

State: the goal index, the answers received so far, and whether the episode has ended. Asking a question
samples the answer from ``P(z | g, q)`` into the next state and the observation reveals it; every other
action ends the episode with its payoff for the goal. Repeated questions are not offered, as in ours.
The payoffs are our model's own numbers, so the peer plans exactly the problem our solver does:

* the commit model (:class:`~sa_daemon.planner.problem.Problem`): a move pays ``M[g, a]``, a question
  ``r_q``, discounted by ``gamma``;
* the watch model (:class:`~sa_daemon.planner.watch_tree.WatchTree`): a commit pays its return over the
  steps left after the questions asked; a question pays ``question_cost``, and one asked with exactly
  ``n_q`` steps left pays ``last_question`` and ends the episode; a watch of a motion (root only) pays its
  payoff for the goal; a node asks only what the tree lets it (the gate, the depth limits);
  undiscounted. The peer's choice of a watch is the watched motion.
"""

from __future__ import annotations

import random
from abc import ABC, abstractmethod

import numpy as np
import pomdp_py

from ..model.actions import Action
from ..planner.problem import Problem
from ..planner.watch_tree import Answers, WatchTree


class _State(pomdp_py.State):
    def __init__(self, goal: int, answers: Answers, done: bool) -> None:
        self.goal, self.answers, self.done = goal, answers, done

    def __hash__(self) -> int:
        return hash((self.goal, self.answers, self.done))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _State) and (self.goal, self.answers, self.done) == (
            other.goal, other.answers, other.done,
        )


class _Action(pomdp_py.Action):
    """One of the game's actions: ``kind`` "commit" (``index`` a move), "question" (``index`` a question)
    or "watch" (``index`` the watched move); ``action`` what the planner would carry out."""

    def __init__(self, uid: int, kind: str, index: int, action: Action) -> None:
        self.uid, self.kind, self.index, self.action = uid, kind, index, action

    def __hash__(self) -> int:
        return self.uid

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Action) and self.uid == other.uid


class _Obs(pomdp_py.Observation):
    def __init__(self, value: str) -> None:
        self.value = value

    def __hash__(self) -> int:
        return hash(self.value)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Obs) and self.value == other.value


class _Game(ABC):
    """The actions, payoffs and answer likelihoods of one problem (module doc)."""

    def __init__(self, b0: np.ndarray, moves: tuple[Action, ...] | list[Action],
                 questions: tuple[Action, ...] | list[Action], watched: list[int], L_yes: np.ndarray,
                 discount: float, max_depth: int) -> None:
        self.b0, self.L_yes, self.discount, self.max_depth = b0, L_yes, discount, max_depth
        acts = [("commit", i, a) for i, a in enumerate(moves)] + [("question", j, q) for j, q in enumerate(questions)]
        acts += [("watch", w, moves[w]) for w in watched]
        self.actions = [_Action(uid, kind, i, a) for uid, (kind, i, a) in enumerate(acts)]

    @abstractmethod
    def legal(self, answers: Answers) -> list[_Action]:
        """The actions the node reached by ``answers`` offers."""

    @abstractmethod
    def payoff(self, goal: int, answers: Answers, a: _Action) -> float:
        """What ``a`` taken after ``answers`` pays if the goal is ``goal``."""

    def ends(self, answers: Answers, a: _Action) -> bool:
        """Whether ``a`` taken after ``answers`` ends the episode."""
        return a.kind != "question"


class _CommitGame(_Game):
    def __init__(self, prob: Problem) -> None:
        super().__init__(prob.b0, prob.moves, prob.questions, [], prob.L_yes, prob.gamma,
                         prob.cfg.planner.max_questions + 1)
        self.p = prob

    def legal(self, answers: Answers) -> list[_Action]:
        asked = {q for q, _ in answers}
        return [a for a in self.actions if a.kind == "commit" or a.index not in asked]

    def payoff(self, goal: int, answers: Answers, a: _Action) -> float:
        return float(self.p.M[goal, a.index]) if a.kind == "commit" else self.p.q_reward


class _WatchGame(_Game):
    def __init__(self, tree: WatchTree) -> None:
        super().__init__(tree.b, tree.moves, tree.questions, sorted(tree.watches), tree.L_yes, 1.0,
                         tree.n // tree.n_q + 1)  # questions that fit the horizon, then the last action
        self.t = tree

    def legal(self, answers: Answers) -> list[_Action]:
        open_q = self.t.open_questions(answers)
        return [a for a in self.actions if a.kind == "commit" or (a.kind == "question" and a.index in open_q)
                or (a.kind == "watch" and not answers)]

    def payoff(self, goal: int, answers: Answers, a: _Action) -> float:
        if a.kind == "commit":
            return float(self.t.value[goal, a.index, self.t.steps_left(answers)])
        if a.kind == "watch":
            return float(self.t.watches[a.index][goal])
        if self.t.steps_left(answers) == self.t.n_q:
            return float(self.t.last_question[goal])
        return float(self.t.question_cost[goal])

    def ends(self, answers: Answers, a: _Action) -> bool:
        return a.kind != "question" or self.t.steps_left(answers) == self.t.n_q


class _Transition(pomdp_py.TransitionModel):
    def __init__(self, game: _Game) -> None:
        self.game = game

    def sample(self, state: _State, action: _Action) -> _State:
        if state.done or self.game.ends(state.answers, action):
            return _State(state.goal, state.answers, True)
        yes = random.random() < self.game.L_yes[action.index, state.goal]
        return _State(state.goal, state.answers | {(action.index, yes)}, False)


class _Observation(pomdp_py.ObservationModel):
    def sample(self, next_state: _State, action: _Action) -> _Obs:
        if action.kind != "question" or next_state.done:
            return _Obs("none")
        return _Obs("yes" if (action.index, True) in next_state.answers else "no")


class _Reward(pomdp_py.RewardModel):
    def __init__(self, game: _Game) -> None:
        self.game = game

    def sample(self, state: _State, action: _Action, next_state: _State) -> float:
        return 0.0 if state.done else self.game.payoff(state.goal, state.answers, action)


class _Policy(pomdp_py.RolloutPolicy):
    def __init__(self, game: _Game) -> None:
        self.game = game

    def get_all_actions(self, state: _State | None = None, history: tuple | None = None) -> list[_Action]:
        if state is None:
            return self.game.actions
        return self.game.legal(state.answers)

    def rollout(self, state: _State, history: tuple | None = None) -> _Action:
        return random.choice(self.get_all_actions(state, history))

    def sample(self, state: _State) -> _Action:
        return self.rollout(state)


def _plan(game: _Game, budget_s: float | None, exploration_const: float, seed: int, sims: int | None = None) -> Action:
    """POUCT's root choice within ``budget_s`` seconds, or after ``sims`` simulations (deterministic)."""
    random.seed(seed)
    belief = pomdp_py.Histogram({_State(g, frozenset(), False): float(p) for g, p in enumerate(game.b0) if p > 0})
    agent = pomdp_py.Agent(belief, _Policy(game), _Transition(game), _Observation(), _Reward(game))
    planner = pomdp_py.POUCT(
        max_depth=game.max_depth,
        discount_factor=game.discount,
        planning_time=-1 if sims is not None else budget_s,
        num_sims=-1 if sims is None else sims,
        exploration_const=exploration_const,
        rollout_policy=agent.policy_model,
    )
    return planner.plan(agent).action


def pouct_plan(prob: Problem, budget_s: float, exploration_const: float = 50.0, seed: int = 0) -> Action:
    """Plan the root action of the commit model's ``prob`` with pomdp_py's POUCT within ``budget_s`` seconds.

    ``exploration_const`` is set to the scale of the rewards (they span about 100 units).
    """
    return _plan(_CommitGame(prob), budget_s, exploration_const, seed)


def pouct_plan_watch(tree: WatchTree, budget_s: float | None, exploration_const: float | None = None,
                     seed: int = 0, sims: int | None = None) -> Action:
    """Plan the root action of the watch model's ``tree`` with pomdp_py's POUCT within ``budget_s`` seconds
    (or ``sims`` simulations, deterministic for a given ``seed``).

    ``exploration_const`` (``None``): the spread of the root's commit values, the scale on which its
    actions differ (returns over the horizon span thousands of units from snapshot to snapshot).
    """
    if budget_s is None and sims is None:
        raise ValueError("pouct_plan_watch: give a budget_s (s) or a number of sims")
    if exploration_const is None:
        commits = tree.b @ tree.value[:, :, tree.n]
        exploration_const = max(float(commits.max() - commits.min()), 1.0)
    return _plan(_WatchGame(tree), budget_s, exploration_const, seed, sims)
