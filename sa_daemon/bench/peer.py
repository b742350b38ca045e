"""The same POMDP for pomdp_py's POUCT: the peer our solver is compared against (``bench planner``).

State: the goal index, the answers received so far, and whether a move ended the episode. Asking a
question samples the answer from ``P(z | g, q)`` into the next state and the observation reveals it;
a move is terminal with reward ``M[g, a]`` (the same matrix our solver uses, from the same
:class:`~sa_daemon.planner.problem.Problem`). Repeated questions are not offered, as in ours.
"""

from __future__ import annotations

import random

import pomdp_py

from ..model.actions import Action
from ..planner.problem import Problem


class _State(pomdp_py.State):
    def __init__(self, goal: int, asked: frozenset[int], done: bool) -> None:
        self.goal, self.asked, self.done = goal, asked, done

    def __hash__(self) -> int:
        return hash((self.goal, self.asked, self.done))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _State) and (self.goal, self.asked, self.done) == (
            other.goal, other.asked, other.done,
        )


class _Action(pomdp_py.Action):
    def __init__(self, index: int, action: Action) -> None:
        self.index, self.action = index, action

    def __hash__(self) -> int:
        return self.index

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Action) and self.index == other.index


class _Obs(pomdp_py.Observation):
    def __init__(self, value: str) -> None:
        self.value = value

    def __hash__(self) -> int:
        return hash(self.value)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Obs) and self.value == other.value


class _Models:
    """Transition, observation, reward and rollout policy over one :class:`Problem`."""

    def __init__(self, prob: Problem) -> None:
        self.p = prob
        n_moves = len(prob.moves)
        self.actions = [_Action(i, a) for i, a in enumerate(prob.moves)]
        self.actions += [_Action(n_moves + j, q) for j, q in enumerate(prob.questions)]
        self.n_moves = n_moves

    def question(self, a: _Action) -> int:
        return a.index - self.n_moves


class _Transition(pomdp_py.TransitionModel):
    def __init__(self, m: _Models) -> None:
        self.m = m

    def sample(self, state: _State, action: _Action) -> _State:
        if state.done or action.index < self.m.n_moves:
            return _State(state.goal, state.asked, True)
        q = self.m.question(action)
        p_yes = self.m.p.L_yes[q, state.goal]
        answer = (q, random.random() < p_yes)
        return _State(state.goal, state.asked | {answer}, False)


class _Observation(pomdp_py.ObservationModel):
    def __init__(self, m: _Models) -> None:
        self.m = m

    def sample(self, next_state: _State, action: _Action) -> _Obs:
        if action.index < self.m.n_moves or next_state.done:
            return _Obs("none")
        q = self.m.question(action)
        yes = (q, True) in next_state.asked
        return _Obs("yes" if yes else "no")


class _Reward(pomdp_py.RewardModel):
    def __init__(self, m: _Models) -> None:
        self.m = m

    def sample(self, state: _State, action: _Action, next_state: _State) -> float:
        if state.done:
            return 0.0
        if action.index < self.m.n_moves:
            return float(self.m.p.M[state.goal, action.index])
        return self.m.p.q_reward


class _Policy(pomdp_py.RolloutPolicy):
    def __init__(self, m: _Models) -> None:
        self.m = m

    def get_all_actions(self, state: _State | None = None, history: tuple | None = None) -> list[_Action]:
        if state is None:
            return self.m.actions
        asked = {q for q, _ in state.asked}
        return [a for a in self.m.actions if a.index < self.m.n_moves or self.m.question(a) not in asked]

    def rollout(self, state: _State, history: tuple | None = None) -> _Action:
        return random.choice(self.get_all_actions(state, history))

    def sample(self, state: _State) -> _Action:
        return self.rollout(state)


def pouct_plan(prob: Problem, budget_s: float, exploration_const: float = 50.0, seed: int = 0) -> Action:
    """Plan the root action of ``prob`` with pomdp_py's POUCT within ``budget_s`` seconds.

    ``exploration_const`` is set to the scale of the rewards (they span about 100 units).
    """
    random.seed(seed)
    m = _Models(prob)
    belief = pomdp_py.Histogram({_State(g, frozenset(), False): float(p) for g, p in enumerate(prob.b0)})
    agent = pomdp_py.Agent(belief, _Policy(m), _Transition(m), _Observation(m), _Reward(m))
    planner = pomdp_py.POUCT(
        max_depth=prob.cfg.planner.max_questions + 1,
        discount_factor=prob.gamma,
        planning_time=budget_s,
        exploration_const=exploration_const,
        rollout_policy=agent.policy_model,
    )
    return planner.plan(agent).action
