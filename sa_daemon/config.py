"""Configuration: one pydantic model, loaded from TOML, with the paper's constants as defaults.

Every section refuses unknown keys and every error names the offending key as a dotted path
(``reward.beta: Input should be greater than 0``). ``config.toml`` at the repository root documents
each value; ``tests/test_config.py`` checks that it equals these defaults.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

# The one registry of arm backends and the one list of methods; neither imports the package at load time.
from .arm.backends import BACKENDS
from .model.methods import METHODS

PositiveFloat = float


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class HuberConfig(_Section):
    """Huber value function ``V(d)`` of Javdani et al.: quadratic within ``delta``, linear beyond."""

    c: float = Field(gt=0, description="linear multiplier c")
    delta: float = Field(gt=0, description="switch distance (m or rad)")
    a: float = Field(ge=0, description="constant added slope a")
    weight: float = Field(1.0, gt=0, description="multiplier of the whole term")


class IntentConfig(_Section):
    """MaxEnt IOC belief update from joystick input and answers (section III-D, HO reference)."""

    translation: HuberConfig = HuberConfig(c=2.25, delta=0.07, a=0.2, weight=1.0)
    rotation: HuberConfig = HuberConfig(c=0.20, delta=math.pi / 32, a=0.01, weight=0.07)
    action_apply_time_s: float = Field(0.1, gt=0, description="time the user's twist is applied in Q (s)")
    cap: float = Field(0.99, gt=0, lt=1, description="maximum probability of one goal")
    answer_p_correct: float = Field(0.999, gt=0.5, lt=1, description="P(yes | asked goal is the goal)")
    reading_trust: float = Field(
        1.0, gt=0, le=1,
        description="the prior probability that the tracker reads this person's input soundly; below 1 a 'no' "
        "to a target the belief held likely is evidence it does not, and the open targets' probability is "
        "mixed toward uniform over them by the posterior doubt (docs/model.md, A surprising no); 1 = the "
        "paper's answers, the default (session 51, screened)",
    )
    resample: bool = Field(True, description="resample and redistribute grasp poses (section III-G)")
    rotation_weight_m_per_rad: float = Field(
        0.05, ge=0, description="weight of rotation distance when picking k_c (m per rad)"
    )
    step_cost: Literal["time", "path"] = Field(
        "path",
        description="cost of the user's step in Q: time = T x slope of V whatever the input (Javdani's); "
        "path = T x slope x |u| (proportional to the distance the input moves the gripper)",
    )
    rationality: float = Field(
        10.0, gt=0, description="beta in P(u | g) ~ exp(-beta (Q_g - V_g)), per input sample (docs/model.md, The tracker)"
    )
    rotation_rationality: float = Field(
        200.0, gt=0,
        description="beta of the rotation part of Q_g - V_g (rotation-mode input), per input sample; rationality "
        "weighs the translation part (docs/model.md, The tracker)",
    )
    poses: Literal["nearest", "marginal", "tracked", "switching", "points"] = Field(
        "marginal",
        description="a goal with several grasp poses: nearest = V and Q from its lowest-value pose (Javdani's); "
        "marginal = P(u | g) sums P(u | pose) over its poses, weighted exp(-V); tracked = weighted by the "
        "goal's posterior over its poses from the input so far; switching = that posterior with the pose "
        "free to change at every sample (pose_switch); points = exp(-V) summed over each grasp point's "
        "listings, shared among them by their posterior (sessions 18 and 46, off; docs/model.md, The tracker)",
    )
    pose_switch: float = Field(
        0.025, ge=0, le=1,
        description="poses = switching: the probability, per input sample, that the user's grasp pose is drawn "
        "afresh from the weights exp(-V) before the sample is read (0 = tracked, 1 = marginal); 0.025 = a "
        "memory of about 1 s at 40 samples a second",
    )
    user_standoff_m: float = Field(
        0.06, ge=0, le=0.3,
        description="the user translates to this far behind a grasp along its approach first (m): the watch model's "
        "predicted user heads there, and a turn there is a turn at the goal (turn_charge)",
    )
    turn_charge: float = Field(
        0.0, ge=0, le=1,
        description="while the input turns without moving, each goal is charged this share of the time form's "
        "translation step cost (T x slope of V) at the distance from where the user last translated to the "
        "nearer of its grasp and its pre-grasp point: time spent turning is not spent approaching; 0 = the "
        "paper's MaxEnt IOC, the default (measured in sessions 22-23 and left off; docs/model.md, The tracker)",
    )
    reach_pose: Literal["closest", "tracked", "tracked_moves"] = Field(
        "tracked_moves",
        description="the grasp pose a goal is driven to and scored at: tracked_moves = the pose the input since "
        "the last resampling points at (each goal's posterior over its poses times exp(-V) at the gripper) for the "
        "moves and the planner's rollouts, HO keeping the paper's lowest-value poses (the default since session "
        "43, docs/results.md); closest = the paper's k_c for the moves and the rollouts (closest by distance) "
        "and each goal's lowest-value pose for HO; tracked = the tracked pose for HO too (docs/model.md, One "
        "grasp pose for HO, the moves and the rollouts)",
    )
    copy_reach: Literal["own", "target", "likeliest", "pooled", "ranked"] = Field(
        "own",
        description="which grasp pose the copies resampling makes of one target (section III-G) are driven to "
        "and scored at, by the moves and the planner's rollouts: own = each copy its own (each copy a goal of "
        "its own, the default); target = with reach_pose = closest the closest over all the target's poses "
        "(screened in session 30 and left off), with a tracked reach the pose of highest P(copy) P(pose | copy, input) "
        "w(pose | copy) over all the target's copies, w the copy's weights exp(-V) at the gripper normalised "
        "over its own poses (session 45, screened, off); likeliest = the k_c (or tracked pose) of the "
        "target's most probable copy; pooled = with a tracked reach, the pose of highest P(pose | target, input) "
        "exp(-V) over all the target's poses, the belief keeping each target's posterior over its poses across "
        "its copies; ranked = each copy its own tracked pose, and the planner deals each target's probability to its "
        "copies by that posterior times exp(-V) over their poses (the belief's own as copy_weights says) "
        "(pooled and ranked: session 45, screened, off; docs/model.md, Copies that share one k_c)",
    )
    copy_weights: Literal["equal", "poses", "input", "tracked"] = Field(
        "poses",
        description="a target's probability over the copies resampling makes of it (section III-G): equal = "
        "the same share each (the paper's Fig. 2); poses = each copy's share of the target's grasp-pose weights "
        "exp(-V) at the gripper, so the next input's likelihood is the same before and after (the default since "
        "session 37, docs/results.md); input = each copy's share of "
        "the target's posterior over its grasp poses from the input since the last resampling, so a split "
        "keeps what the input said about the pose (docs/model.md); tracked = each copy's share of that posterior "
        "times the weights exp(-V) at the gripper, the score the tracked reach picks a pose by (session 44, "
        "screened, off)",
    )
    keep_pose_posterior: bool = Field(
        True,
        description="a resampling keeps, for each copy it makes, the target's posterior over the copy's own grasp "
        "poses from the input so far (with copy_weights equal or poses the copies' probabilities are as those "
        "say; input keeps it already; the default since session 43); false = each copy's pose weights start "
        "afresh. Read where the pose posterior is kept (reach_pose tracked or tracked_moves, or poses tracked; "
        "session 42, docs/results.md)",
    )

    @property
    def rotation_scale(self) -> float:
        """``rotation_rationality / rationality``: the rotation part's weight in ``Q_g - V_g`` relative to the
        translation part's, the scale the tracker and the watch model's rollouts both apply."""
        return self.rotation_rationality / self.rationality


class HOConfig(_Section):
    """Hindsight-optimisation assistance twist (Javdani et al.)."""

    translation_cost_multiplier: float = Field(40.0, gt=0)
    rotation_cost_multiplier: float = Field(0.05, gt=0)
    translation_shrink_m: float = Field(0.02, gt=0, description="gradient shrinks linearly inside this (m)")
    rotation_shrink_rad: float = Field(math.pi / 12, gt=0, description="gradient shrinks inside this (rad)")
    generator: Literal["gradient", "moves"] = Field(
        "moves",
        description="gradient = the belief-weighted mean of Javdani's -dQ/du; moves = the move-to-goal generator "
        "applied to the belief-weighted mean error (same gain and top speed as a move)",
    )


class MoveConfig(_Section):
    """Move-to-goal velocity generator: proportional toward ``k_c``, saturated.

    The saturations sit below the user's full deflection (``input``) so that, blended at ``alpha = 0.5``,
    the user can always overpower a wrong assistance: it may slow the user, never block them.
    """

    linear_gain: float = Field(1.0, gt=0, description="1/s")
    linear_max_mps: float = Field(0.15, gt=0)
    angular_gain: float = Field(1.0, gt=0, description="1/s")
    angular_max_radps: float = Field(0.3, gt=0)
    approach_standoff_m: float = Field(
        0.0, ge=0, le=0.3,
        description="m; > 0: moves and HO head for a point this far behind the grasp along its approach axis "
        "until the gripper is on that axis (twists.approach_points); 0 = straight to the grasp (the paper)",
    )
    approach_funnel: float = Field(
        2.0, gt=0, description="the point behind the grasp is this many times the gripper's distance from the axis",
    )
    approach_turn_m: float = Field(
        0.08, ge=0, le=0.5,
        description="m; the point stays at least this times sin(orientation error, at most 90 deg) behind the grasp",
    )


class BlendConfig(_Section):
    """Arbitration (section III-B) and the predict-then-act baseline."""

    alpha: float = Field(0.5, ge=0, le=1, description="a_total = (1 - alpha) a_h + alpha a_r")
    predict_margin: float = Field(0.4, ge=0, le=1, description="blend: assist when p1 - p2 > margin")
    yield_near_m: float = Field(
        0.0, ge=0, le=0.5,
        description="the robot stops assisting within this distance (m) of a grasp pose of the most likely object, "
        "when that object holds yield_near_belief of the belief; 0 = never (the paper)",
    )
    yield_near_belief: float = Field(0.8, gt=0.5, le=1, description="the belief share the most likely object needs")
    opposition_window_s: float = Field(
        0.0, ge=0, le=10,
        description="the robot yields while the user has opposed its assistance in opposition_share of the control "
        "periods with input over this window (s); 0 = opposition only costs in the planner's reward (the paper)",
    )
    opposition_share: float = Field(0.8, gt=0, le=1, description="the share of opposed periods that makes the robot yield")
    churn_window_s: float = Field(
        10.0, ge=0, le=60,
        description="the robot yields while the user has switched joystick mode churn_switches times within this "
        "window (s): a user turning, translating and turning again because the assistance undoes, in the mode "
        "they left, a grasp pose of their own (the default since session 49, docs/model.md); 0 = never (the paper)",
    )
    churn_switches: int = Field(6, ge=2, le=100, description="the mode switches within churn_window_s that make the robot yield")
    churn_counts: Literal["switches", "driven"] = Field(
        "switches",
        description="which mode switches churn_switches counts: 'switches' every one (session 49); 'driven' a "
        "change of the mode the user gives input in, so a switch out and back without input (a glance at the "
        "other mode) counts none (session 50, docs/model.md)",
    )


class RewardConfig(_Section):
    """Reward of section III-E."""

    scale: float = Field(100.0, gt=0, description="R_t = -scale (1 - 2^(-beta d))")
    beta: float = Field(8.0, gt=0, description="1/m")
    rotation_threshold_m: float = Field(0.1, gt=0, description="delta: R_r applies when d_trans <= delta")
    opposition_penalty: float = Field(-5.0, le=0)
    opposition_threshold: float = Field(0.01, ge=0, description="|a_i| above this in both twists")
    opposition_every_step: bool = Field(
        True, description="charge the opposition penalty at every lookahead step it is predicted (false: the first only)"
    )
    question: float = Field(-5.0, le=0)
    question_time_s: float = Field(
        2.0, ge=0,
        description="time a question stops the arm (s): the watch model charges R_d there for this long (a "
        "whole number of planner.rollout_step_s steps, at least one); the commit model charges this share of "
        "the best move's gain",
    )
    repeated_question: float = Field(-100.0, le=0)
    goal: float = Field(100.0, ge=0, description="reward for reaching the desired pose")
    goal_translation_m: float = Field(0.01, gt=0)
    goal_rotation_rad: float = Field(math.pi / 48, gt=0)
    gamma: float = Field(0.95, gt=0, le=1)
    step_s: float = Field(0.1, gt=0, description="duration of one planning step (s)")
    lookahead_steps: int = Field(
        15, ge=1, le=100, description="H: a move is judged at its pose after H steps (1 = literal reading)"
    )
    discount_lookahead: bool = Field(
        False, description="a move's reward arrives when its pose is reached: discounted by gamma^H"
    )


class PlannerConfig(_Section):
    """Anytime solver settings."""

    top_goals: int = Field(10, ge=1, le=64, description="G_m: goals with move and question actions")
    rank_goals: Literal["goal", "lead", "target", "cover"] = Field(
        "cover",
        description="what ranks the top G_m goals (section III-B, ties by distance to the gripper): goal = each "
        "goal's own probability; lead = the same, but a target resampling split into copies (section III-G) "
        "has its likeliest copy ranked by the whole target's probability; target = every goal by its "
        "target's probability, then its own; cover = goal's, but the likeliest copy of each of the "
        "cover_targets likeliest targets always among them, the default since session 33 (chosen by rule s32, "
        "written before its run; docs/model.md, The top goals of a split target)",
    )
    cover_targets: int = Field(
        2, ge=1, le=64, description='with rank_goals = "cover": how many of the likeliest targets keep their '
        "likeliest copy among the top G_m goals (2, chosen before any run: the issue's two likeliest)",
    )
    budget_s: float = Field(0.1, gt=0, le=1.0, description="wall-clock budget of one plan (s)")
    period_s: float = Field(0.1, ge=0.1, le=0.3, description="planning period (s)")
    max_questions: int = Field(
        5, ge=0, le=64, description="deepest chain of questions searched (the authors' HyP-DESPOT depth, 5)"
    )
    bound_levels: int = Field(3, ge=0, le=6, description="how far the solver refines its question bounds")
    model: Literal["commit", "watch"] = Field(
        "watch",
        description="commit: moves end the search (H-step lookahead); watch: motion for watch_s, then the "
        "predicted joystick evidence, then ask or move, over a horizon of horizon_s (docs/model.md)",
    )
    horizon_s: float = Field(5.0, gt=0, le=20, description="watch model: every plan is judged at this time (s)")
    terminal_s: float = Field(
        2.0, ge=0, le=100,
        description="watch model: a plan's last pose is charged R_d for this long after the horizon (s)",
    )
    terminal: Literal["fixed", "approach"] = Field(
        "fixed",
        description="watch model: what a plan's last pose is worth after the horizon. fixed: R_d there for "
        "terminal_s; approach: the return of finishing the approach at the assisted speed, goal bonus "
        "included (model.reward.approach_return; docs/model.md)",
    )
    switch_margin: float = Field(
        0.0, ge=0, le=1000,
        description="the adopted motion (a move, HO or no-assist) is kept while the new plan's motion beats it by "
        "less than this (reward units): the arm's direction does not flip on near ties; questions are not held "
        "back; 0 = every plan free (the paper) (session 42, docs/model.md)",
    )
    watch_s: float = Field(1.0, gt=0, le=5, description="watch model: how long a motion runs before deciding again (s)")
    watch_levels: int = Field(
        1, ge=0, le=2,
        description="watch model: 1 = a motion may be watched before deciding; 2 = and, once watched, watched "
        "once more before deciding (the watch continued: each child may keep its motion for watch_s; session 41, "
        "docs/model.md; needs watch_branches top or all); 0 = no watching",
    )
    watch_moves: int = Field(
        3, ge=0, le=64, description="watch model: moves to this many most likely goals may be watched (HO, no-assist always)"
    )
    watch_likelihood: Literal["kc", "marginal"] = Field(
        "kc",
        description="watch model: how a rollout reads the input it predicts for a user heading to a goal. kc: "
        "MaxEnt IOC against each goal's k_c alone; marginal: the tracker's own likelihood (intent.poses = "
        "marginal), each goal's grasp poses summed with weights exp(-V), so copies of one target that the "
        "tracker cannot tell apart are not expected to part (measured in session 30 and left off; "
        "docs/model.md)",
    )
    watch_evidence: float = Field(
        0.5, ge=0, le=1,
        description="watch model: the share of the predicted input's log-likelihood a watched branch's belief "
        "takes. 1 = all of it, a user heading exactly to the goal (until session 31); the population's input "
        "gives 0.08-1.00 of it (docs/results/evidence.py); 0.5 adopted by session 29's rule on fresh seeds "
        "(session 31, docs/model.md)",
    )
    watch_evidence_rotation: float | None = Field(
        None, ge=0, le=1,
        description="watch model: the share in rotation mode, where it differs from watch_evidence (None: the "
        "same). The population's turning gives less of what the watch predicts than its translating, and on "
        "the drill's orientation twins far less (docs/results/evidence.py by mode; docs/model.md, session 36)",
    )
    watch_copy_evidence: float = Field(
        1.0, ge=0, le=1,
        description="watch model: the share of that evidence that splits copies of one target (resampled grasp "
        "poses, III-G); each target's mass is updated with all of it. 1 = copies part as the input predicts; "
        "0 = the watch expects them to keep the plan's split (session 31, docs/model.md)",
    )
    watch_branches: Literal["top", "mapped", "all"] = Field(
        "top",
        description="watch model: the goals a watched motion's value is averaged over. top: the top G_m goals "
        "(one child each), the belief renormalised over them, where commits and questions average over every "
        "goal; mapped: every goal the belief holds, each outside the top G_m read through the child of the "
        "top goal its predicted input is likeliest for (no more children); all: every goal its own child "
        "(exact, about three times the plan time on 22 goals) (session 34, docs/model.md)",
    )
    question_gate: Literal["none", "information"] = Field(
        "information",
        description="watch model: which questions a node may choose. none: any, by its value; information: only "
        "one whose answers are worth more than its cost (-reward.question) over standing still as long and "
        "deciding without them, so that a question is never chosen for the standing still alone, e.g. about a "
        "target the belief has ruled out (session 34; the default since session 35, by rule s32 on seeds 1000+, "
        "docs/results.md)",
    )
    root_goals: Literal["all", "top"] = Field(
        "all",
        description="watch model: the belief the root's commits and questions are averaged by. all: every goal "
        "the belief holds; top: the belief renormalised over the watch's branches, so that with watch_branches "
        "= top every root action is averaged over the same goals (session 34, docs/model.md)",
    )
    rollout_step_s: float = Field(1.0, gt=0, le=1, description="watch model: integration step of the rollouts (s)")
    threads: int = Field(
        0, ge=0, le=64,
        description="watch model: threads the compiled rollouts are split over (the results do not "
        "depend on it); 0 = one per core this process may use. The evaluation gives each of its jobs its share",
    )
    ho_belief: Literal["tracked", "fixed"] = Field(
        "tracked",
        description="watch model: HO in a rollout follows the belief the tracker reaches from the predicted input "
        "(tracked, as the daemon's HO does) or keeps the plan's belief (fixed)",
    )
    user_speed_tau_s: float = Field(
        1.0, gt=0, description="time constant of the user's smoothed speed the predicted user twists use (s)"
    )
    user_speed_idle: Literal["decay", "hold"] = Field(
        "decay",
        description="the smoothed speed over ticks without input: decay (averaged in as zero: a pausing user is "
        "predicted to stay still) or hold (left as it was: the speed the user moves at when it moves)",
    )
    user_speed_unused: Literal["zero", "deflection"] = Field(
        "deflection",
        description="the predicted speed in a mode the user has not been in yet in this task: zero (the user is "
        "predicted not to move in it: at the first switch to rotation a watch expects no evidence) or deflection "
        "(the stick held as far as in the other mode: v_other / scale_other x scale_this, input.*_scale_*; "
        "session 35, docs/model.md; the default since session 37)",
    )

    @model_validator(mode="after")
    def _continued_watch(self) -> PlannerConfig:
        if self.watch_levels > 1 and self.watch_branches == "mapped":
            raise ValueError('watch_levels = 2 needs watch_branches "top" or "all" (a continued watch branches '
                             'over its own goals)')
        return self


class InputConfig(_Section):
    """Joystick scaling: one unit of axis deflection is this twist."""

    linear_scale_mps: float = Field(0.2, gt=0)
    angular_scale_radps: float = Field(0.4, gt=0)
    filter_hz: float = Field(
        0.0, ge=0, le=50,
        description="first-order low-pass on the stick against tremor, cutoff (Hz); 0 = off. Its delay at low "
        "frequencies is 1 / (2 pi filter_hz) s (docs/profiles.md)",
    )


class LimitsConfig(_Section):
    """Cartesian velocity limits of the arm, applied to every command (m/s, rad/s, per axis)."""

    linear_mps: float = Field(0.25, gt=0, description="per-axis linear speed limit (m/s)")
    angular_radps: float = Field(1.0, gt=0, description="per-axis angular speed limit (rad/s)")
    tcp_mps: float = Field(
        0.25, gt=0, le=1.0,
        description="TCP speed limit, the norm of the linear part (m/s); the xArm controller's reduced TCP speed",
    )


class SimUserConfig(_Section):
    """The simulated user of ``docs/simulated-user.md``."""

    max_deflection: float = Field(
        0.09, gt=0, le=1, description="usual stick deflection (calibrated to the paper's manual input rate)"
    )
    linear_gain: float = Field(5.0, gt=0, description="desired twist = gain * error (1/s)")
    angular_gain: float = Field(5.0, gt=0, description="1/s")
    reaction_delay_s: float = Field(0.15, ge=0, le=1.0, description="the user acts on the pose seen this long ago")
    noise_std: float = Field(0.06, ge=0, le=0.5, description="Gaussian noise on each axis (joystick units)")
    mode_switch_s: float = Field(0.5, ge=0, description="time without input to switch mode (s)")
    answer_delay_s: float = Field(1.5, ge=0, description="time to answer a question (s)")
    answer_error_rate: float = Field(0.0, ge=0, le=1, description="probability of a wrong answer")
    persist_window_s: float = Field(1.0, gt=0, description="a user who saw no progress over this long ...")
    persist_progress: float = Field(
        0.5, ge=0, lt=1, description="... (error shrank by less than this fraction of its own commanded motion)"
    )
    blocked_rotate_s: float = Field(
        2.0, gt=0, description="the arm refuses the approach (safety halt) this long: rotate first (s)"
    )
    pregrasp_standoff_m: float = Field(0.06, ge=0, description="first translate to this far back along the approach")
    pregrasp_tolerance_m: float = Field(0.02, gt=0, description="then rotate once within this of the pre-grasp point")
    rotation_done_rad: float = Field(math.pi / 96, gt=0, description="rotation is finished within this")
    close_translation_m: float = Field(0.01, gt=0, description="close the gripper within this ...")
    close_rotation_rad: float = Field(math.pi / 48, gt=0, description="... and this of the desired pose")
    timeout_s: float = Field(100.0, gt=0, description="a trial fails after this long")
    # -- the population's behaviours (docs/simulated-user.md, "Users"); the defaults are the calibrated user
    order: Literal["translate_first", "rotate_first"] = Field(
        "translate_first", description="translate to the pre-grasp point first, or align the gripper first"
    )
    one_axis: bool = Field(False, description="push only the axis with the largest error at a time")
    burst_s: float = Field(0.0, ge=0, description="push in bursts this long (s; 0: continuously) ...")
    burst_pause_s: float = Field(0.0, ge=0, description="... separated by releases this long (s)")
    tremor_std: float = Field(0.0, ge=0, le=1, description="tremor amplitude per axis (joystick units, std)")
    tremor_hz: float = Field(5.0, gt=0, le=20, description="tremor frequency (Hz)")
    corrective_switch_hz: float = Field(
        0.0, ge=0, description="rate of extra mode switches to check the other mode and back (1/s)"
    )
    pose_choice: Literal["closest", "other", "off_list", "random"] = Field(
        "closest", description="which pose of its goal it wants (closest by k_c's metric, another, none listed)"
    )
    off_list_m: float = Field(0.02, ge=0, le=0.05, description="off_list: translation from the nearest listed pose (m)")
    off_list_rad: float = Field(
        math.radians(15.0), ge=0, le=math.pi / 4, description="off_list: rotation from the nearest listed pose (rad)"
    )
    start_pause_s: float = Field(0.0, ge=0, description="still this long before its first input (s)")
    mid_pause_s: float = Field(0.0, ge=0, description="still this long once, halfway to the pre-grasp point (s)")
    close_translation_max_m: float | None = Field(
        None, gt=0, le=0.1, description="closes within a tolerance drawn per trial in [close_translation_m, this] (m)"
    )
    answer_delay_max_s: float | None = Field(
        None, ge=0, description="answers after a uniform delay in [answer_delay_s, this] (s; None: always answer_delay_s)"
    )

    @model_validator(mode="after")
    def _answer_delays(self) -> SimUserConfig:
        if self.answer_delay_max_s is not None and self.answer_delay_max_s < self.answer_delay_s:
            raise ValueError("answer_delay_max_s must be at least answer_delay_s")
        if self.close_translation_max_m is not None and self.close_translation_max_m < self.close_translation_m:
            raise ValueError("close_translation_max_m must be at least close_translation_m")
        return self


class EvalConfig(_Section):
    """Evaluation runs (deterministic: the planner stops at a node budget, not a clock)."""

    control_hz: float = Field(40.0, gt=0, description="simulation and joystick sampling rate (Hz)")
    node_budget: int = Field(3000, ge=1, description="belief evaluations per plan in evaluation")


Vec3 = tuple[float, float, float]


class RuntimeConfig(_Section):
    """Rates and timeouts of the daemon's loops (``sa-daemon run``)."""

    control_hz: float = Field(100.0, ge=10, le=500, description="blend, safety and arm command (Hz)")
    belief_hz: float = Field(40.0, gt=0, le=200, description="belief update = joystick sampling rate (Hz)")
    publish_hz: float = Field(30.0, ge=20, le=200, description="state messages on the PUB socket (Hz)")
    question_timeout_s: float = Field(20.0, gt=0, description="an unanswered question is dropped after this (s)")
    worker_hang_s: float = Field(0.5, gt=0, description="a planner silent this long past its deadline is killed (s)")
    worker_start_timeout_s: float = Field(30.0, gt=0, description="time a new planner worker has to come up (s)")
    worker_nice: int = Field(5, ge=0, le=19, description="niceness added to the planner worker (lower priority)")
    realtime_priority: int = Field(
        0, ge=0, le=99,
        description="SCHED_FIFO priority of the event-loop thread once running (0 = off; needs root or LimitRTPRIO)",
    )
    gil_switch_interval_s: float = Field(
        5e-4, gt=0, le=0.1,
        description="the longest a thread holds the interpreter lock while another waits for it (s; Python's default "
                    "is 5 ms, half a control period)",
    )


class SafetyConfig(_Section):
    """The safety pipeline every arm command passes through (``docs/safety.md``; MoveIt Servo's values)."""

    stale_command_s: float = Field(0.1, gt=0, description="no fresh input for this long: command zero (s)")
    linear_accel_mps2: float = Field(1.0, gt=0, description="per-axis linear acceleration limit (m/s^2)")
    angular_accel_radps2: float = Field(4.0, gt=0, description="per-axis angular acceleration limit (rad/s^2)")
    workspace_min_m: Vec3 = Field((-0.1, -0.6, 0.0), description="workspace box, lower corner (m, base frame)")
    workspace_max_m: Vec3 = Field((0.8, 0.6, 0.7), description="workspace box, upper corner (m, base frame)")
    characteristic_length_m: float = Field(
        0.3, gt=0, description="divides the Jacobian's linear rows so its condition number is unit-free (m)"
    )
    singularity_slow: float = Field(17.0, gt=1, description="Jacobian condition number where slowing starts")
    singularity_stop: float = Field(30.0, gt=1, description="condition number where motion toward it stops")
    singularity_share: float = Field(
        0.15, ge=0, lt=1, description="a command moves toward a singularity when its share along the weakest "
        "direction exceeds this (MoveIt Servo: 0)"
    )
    joint_margin_rad: float = Field(0.1, ge=0, description="halt a joint moving toward a bound within this (rad)")
    stop_self_test: Literal["auto", "on", "off"] = Field(
        "auto",
        description="no assistance and no motion until a stop has been latched and resumed once (button, protocol "
        "or page); auto = on for the real arm, off for the simulated ones",
    )

    @model_validator(mode="after")
    def _check(self) -> SafetyConfig:
        if any(lo >= hi for lo, hi in zip(self.workspace_min_m, self.workspace_max_m)):
            raise ValueError("workspace_min_m must be below workspace_max_m on every axis")
        if self.singularity_stop <= self.singularity_slow:
            raise ValueError("singularity_stop must exceed singularity_slow")
        return self


class MujocoConfig(_Section):
    """The MuJoCo xArm-6 (``--arm mujoco``)."""

    timestep_s: float = Field(0.002, gt=0, le=0.01, description="physics step (s)")
    viewer: bool = Field(False, description="open the passive viewer (needs a display)")


class XArmConfig(_Section):
    """The real xArm-6 through the xArm Python SDK (``--arm xarm``, extra ``xarm``)."""

    ip: str = Field("192.168.1.185", min_length=1, description="controller address")
    sdk: Literal["real", "fake"] = Field(
        "real", description="real: the xArm SDK (extra xarm); fake: sa_daemon/testing/fake_xarm.py, for tests and demos"
    )
    command_periods: float = Field(3.0, ge=1, le=20, description="command duration = this many control periods")
    gripper_speed: float = Field(2000.0, gt=0, le=5000, description="SDK gripper speed (r/min)")
    reconnect_min_s: float = Field(0.5, gt=0, description="first reconnect delay; doubles up to the max (s)")
    reconnect_max_s: float = Field(8.0, gt=0, description="longest reconnect delay (s)")
    controller_limits: Literal["set", "verify"] = Field(
        "set",
        description="on every connect and recovery: set the controller's reduced mode, TCP speed, TCP boundary, "
        "collision sensitivity and self-collision detection from config and read them back (set), or only read "
        "them (verify); a disagreement is a fault (docs/xarm.md)",
    )
    fence_margin_m: float = Field(
        0.02, ge=0.005, le=0.2,
        description="the controller's TCP boundary lies this far outside safety.workspace_*_m, so the pipeline "
        "stops first (m)",
    )
    collision_sensitivity: int = Field(3, ge=1, le=5, description="controller collision sensitivity, 1-5 (0 = off is refused)")


class ArmConfig(_Section):
    """Which arm drives the gripper, and its backend settings."""

    backend: str = Field("mujoco", description="kinematic, mujoco or xarm (arm/backends.py's registry)")
    mujoco: MujocoConfig = MujocoConfig()
    xarm: XArmConfig = XArmConfig()

    @field_validator("backend")
    @classmethod
    def _backend(cls, v: str) -> str:
        if v not in BACKENDS:
            raise ValueError(f"must be one of {', '.join(BACKENDS)}, not {v!r}")
        return v


class JoystickConfig(_Section):
    """The evdev joystick (``--input evdev``): 3 axes drive the current mode's twist."""

    device: str = Field("", description="device path (/dev/input/eventN) or name; empty = first with 3 axes")
    axes: tuple[str, str, str] = Field(("ABS_X", "ABS_Y", "ABS_RZ"), description="evdev codes of x, y, z")
    signs: tuple[float, float, float] = Field((1.0, -1.0, 1.0), description="per-axis sign (+1 or -1)")
    deadzone: float = Field(0.05, ge=0, lt=1, description="smooth deadzone (fraction of full deflection)")
    gains: tuple[float, float, float] = Field(
        (1.0, 1.0, 1.0), description="per-axis gain after the deadzone (the result is clamped to [-1, 1])"
    )
    centre: tuple[float, float, float] | None = Field(
        None, description="calibrated raw rest value per axis (sa-daemon calibrate); None = the middle of the range"
    )
    low: tuple[float, float, float] | None = Field(
        None, description="calibrated raw value at full deflection down, per axis; None = the device's minimum"
    )
    high: tuple[float, float, float] | None = Field(
        None, description="calibrated raw value at full deflection up, per axis; None = the device's maximum"
    )
    button_mode: str = Field("BTN_TRIGGER", description="toggle translation/rotation")
    button_gripper: str = Field("BTN_THUMB", description="toggle gripper open/closed")
    button_yes: str = Field("BTN_THUMB2", description="answer yes")
    button_no: str = Field("BTN_TOP", description="answer no")
    button_assist: str = Field("BTN_TOP2", description="assistance on/off")
    button_stop: str = Field("BTN_PINKIE", description="latched stop (released by resume)")
    button_other: str = Field("BTN_BASE", description='answer "that object, another grasp" (asking.third_answer)')
    grab: bool = Field(False, description="exclusive access to the device")
    poll_s: float = Field(1.0, gt=0, description="how often a missing device is looked for (s)")

    @model_validator(mode="after")
    def _check(self) -> JoystickConfig:
        if any(s not in (-1.0, 1.0) for s in self.signs):
            raise ValueError("signs must be +1 or -1 per axis")
        if any(not 0.1 <= g <= 3.0 for g in self.gains):
            raise ValueError("gains must be between 0.1 and 3 per axis")
        calib = (self.low, self.centre, self.high)
        if any(c is not None for c in calib):
            if any(c is None for c in calib):
                raise ValueError("centre, low and high are calibrated together (sa-daemon calibrate): set all three")
            for i, (lo, c, hi) in enumerate(zip(*calib)):  # type: ignore[call-overload]
                if not lo < c < hi:
                    raise ValueError(f"axis {i}: low < centre < high is needed, got {lo}, {c}, {hi}")
        return self


class SpeechConfig(_Section):
    """Spoken questions (espeak-ng, in one dedicated worker thread)."""

    enabled: bool = Field(True, description="speak questions (they are always published as events)")
    rate_wpm: int = Field(150, ge=50, le=400, description="words per minute")
    volume: float = Field(1.0, ge=0, le=1)
    voice: str = Field("", max_length=64, description="espeak-ng voice, e.g. en-us or en-gb-x-rp ('' = espeak-ng's English, en)")
    wav_dir: str = Field("", description="also write each utterance to a WAV file here (empty: no files)")
    play: bool = Field(True, description="play through the sound card (off: WAV files only)")
    library: Literal["auto", "system", "wheel"] = Field(
        "auto", description="espeak-ng library: the system's (libespeak-ng1) when present, else the pip wheel's"
    )


class VoiceConfig(_Section):
    """Answers by voice (``docs/daemon.md``): offline yes/no recognition while a question is pending.

    Needs the ``voice`` extra (pocketsphinx). Audio comes from ``source``: ``alsa`` (``arecord`` on
    ``device``), ``pcm:PATH`` (raw 16-bit mono little-endian PCM at 16 kHz, e.g. a FIFO) or ``wav:PATH``.
    """

    enabled: bool = Field(False, description="listen for spoken yes/no answers to questions")
    source: str = Field("alsa", min_length=1, description="alsa | pcm:PATH | wav:PATH")
    device: str = Field("default", min_length=1, description="ALSA capture device for source alsa (arecord -D)")
    min_confidence: float = Field(
        0.85, ge=0, le=1, description="a recognised yes/no below this confidence is ignored (docs/daemon.md)"
    )
    listen_s: float = Field(8.0, gt=0, le=120, description="listen this long after the question was spoken (s)")
    after_speech_s: float = Field(
        0.3, ge=0, le=5, description="start listening this long after the robot stops speaking (its echo) (s)"
    )
    echo: bool = Field(True, description='say what was heard ("Yes: the cup, top grasp")')
    max_segment_s: float = Field(4.0, gt=0.5, le=30, description="longer speech is not an answer and is ignored (s)")

    @field_validator("source")
    @classmethod
    def _source(cls, v: str) -> str:
        kind, sep, path = v.partition(":")
        if v == "alsa" or (sep and kind in ("pcm", "wav") and path):
            return v
        raise ValueError(f"must be alsa, pcm:PATH or wav:PATH, not {v!r}")


class ZmqConfig(_Section):
    """The ZeroMQ sockets and who may use them (``docs/protocol.md``, section 5).

    ``cmd`` may be a non-loopback endpoint only with CURVE on (``curve_server_secret`` and
    ``curve_clients_dir``, made by ``sa-daemon keygen``): ``sa-daemon run`` refuses to start otherwise.
    ``pub`` is read-only and may be exposed without CURVE. Key paths are files written by
    ``sa-daemon keygen``; relative paths are relative to the working directory (use absolute ones).
    """

    pub: str = Field("tcp://127.0.0.1:5555", min_length=1, description="PUB endpoint (state, event)")
    cmd: str = Field("tcp://127.0.0.1:5556", min_length=1, description="command endpoint (REQ clients)")
    max_request_bytes: int = Field(65536, ge=256, description="longer requests are refused")
    max_json_depth: int = Field(8, ge=1, le=64, description="deeper requests are refused")
    max_requests_per_tick: int = Field(
        16, ge=1, le=10000,
        description="command requests answered per control period at most; the rest wait in ZeroMQ's queue",
    )
    curve_server_secret: str = Field(
        "", description="daemon: its CURVE secret key file (DIR/server.key_secret); '' = CURVE off, cmd loopback only"
    )
    curve_clients_dir: str = Field(
        "", validate_default=True,
        description="daemon: directory of the allowed clients' public keys (*.key); needs curve_server_secret",
    )
    curve_pub: bool = Field(
        True, description="with CURVE on, the PUB stream is encrypted and readable by allowed clients only"
    )
    curve_client_secret: str = Field(
        "", description="answer/monitor: this client's CURVE secret key file (DIR/clients/NAME.key_secret)"
    )
    curve_server_public: str = Field(
        "", validate_default=True,
        description="answer/monitor: the daemon's public key file (DIR/server.key); needs curve_client_secret",
    )

    @field_validator("curve_clients_dir")
    @classmethod
    def _clients_dir_with_server_key(cls, v: str, info: ValidationInfo) -> str:
        return _paired(v, info.data.get("curve_server_secret"), "curve_clients_dir", "curve_server_secret")

    @field_validator("curve_server_public")
    @classmethod
    def _server_public_with_client_key(cls, v: str, info: ValidationInfo) -> str:
        return _paired(v, info.data.get("curve_client_secret"), "curve_server_public", "curve_client_secret")


def _paired(value: str, other: str | None, key: str, other_key: str) -> str:
    """Two key-file settings that only make sense together: both set or both empty."""
    if other is None:  # the other key failed its own validation, which is reported
        return value
    if other and not value:
        raise ValueError(f"required when zmq.{other_key} is set (sa-daemon keygen prints both)")
    if value and not other:
        raise ValueError(f"needs zmq.{other_key} too (sa-daemon keygen prints both)")
    return value


class RecordConfig(_Section):
    """MCAP recording of state (control rate) and events."""

    path: str = Field("", description="MCAP file ('' = no recording; {time} is replaced by a timestamp)")
    flush_s: float = Field(1.0, gt=0, le=10, description="data reaches the disk at least this often (s)")


class FoxgloveConfig(_Section):
    """The live view for Foxglove (``docs/foxglove.md``): a WebSocket server on 127.0.0.1 only."""

    enabled: bool = Field(False, description="serve the live view (run --foxglove)")
    port: int = Field(8765, ge=0, le=65535, description="its TCP port on 127.0.0.1 (0: any free port)")
    scene_period_s: float = Field(1.0, gt=0, le=10, description="the table, objects and grasp poses are re-sent "
                                  "at least this often (s), so a viewer that connects late sees them")
    belief_step: float = Field(0.01, gt=0, le=1, description="... and whenever a target's probability moved by "
                               "more than this since they were last drawn")


class AskingConfig(_Section):
    """What a person wants of the questions (their profile, ``docs/profiles.md``)."""

    max_per_task: int = Field(0, ge=0, le=100, description="questions per task at most (0 = as the planner decides)")
    third_answer: bool = Field(
        False, description='a third answer, "yes, that object, but another grasp" (the paper: yes or no only)'
    )
    withdraw_yes_s: float = Field(
        2.0, ge=0, le=30,
        description='a "yes" stops being final once the user has opposed the assistance in blend.opposition_share '
        "of the control periods with input over this window (s): a misheard or mistaken yes no longer holds the "
        "arm on the wrong target; 2 s by default since session 33 (chosen by rule s32, written before its run; "
        "docs/model.md), 0 = a yes is final (our reading of section III-B)",
    )
    withdraw_no_s: float = Field(
        2.0, ge=0, le=30,
        description='the "no" answers stop being final once, with no "yes" holding, the user has opposed the '
        "assistance in blend.opposition_share of the control periods with input over this window (s): a "
        "misheard or mistaken no about the person's goal no longer keeps the arm from it; 2 s by default since "
        "session 28 (chosen by a rule written before its run; docs/model.md), 0 = a no is final (our reading)",
    )
    learn_answer_time: bool = Field(
        True, description="the planner charges a question this person's median answer time, the prior "
        "reward.question_time_s counted as one answer, rounded up to whole planner.rollout_step_s steps "
        "(control/answer_time.py; a prior of 0 stays 0); the count goes on across tasks and starts again at a "
        "profile switch; the default since session 39 (rule s39b, written before its run; docs/results.md), "
        "false = always reward.question_time_s",
    )
    answer_sources: tuple[Literal["button", "command", "voice"], ...] = Field(
        ("button", "command", "voice"),
        description="where answers are taken from: the joystick's buttons, the protocol (and the page), the voice",
    )


class ProfilesConfig(_Section):
    """Where ``run --profile NAME`` finds ``NAME.toml`` (``docs/profiles.md``)."""

    dir: str = Field("/etc/sa-daemon/profiles", description="directory of the per-person profiles")


class WebConfig(_Section):
    """``sa-daemon web``: the page for the carer and the researcher (``docs/web.md``).

    It listens on loopback unless TLS (``tls_cert``, ``tls_key``) and a token (``token_file``, made by
    ``sa-daemon keygen DIR --web-token``) are set; ``web`` refuses a non-loopback ``listen`` without
    them. With a token every request needs it (the page's address carries it once, then a cookie).
    """

    listen: str = Field("127.0.0.1:8080", min_length=3, description="HOST:PORT the page is served on")
    tls_cert: str = Field("", description="PEM certificate file ('' = plain HTTP, loopback only)")
    tls_key: str = Field("", description="PEM private key file of tls_cert")
    token_file: str = Field("", description="file holding the access token ('' = none, loopback only)")
    max_message_bytes: int = Field(4096, ge=64, le=65536, description="longer page messages are refused")




class Config(_Section):
    """The whole configuration."""

    method: str = Field("policy", description="assistance method, one of METHODS")
    intent: IntentConfig = IntentConfig()
    ho: HOConfig = HOConfig()
    move: MoveConfig = MoveConfig()
    blend: BlendConfig = BlendConfig()
    reward: RewardConfig = RewardConfig()
    planner: PlannerConfig = PlannerConfig()
    input: InputConfig = InputConfig()
    limits: LimitsConfig = LimitsConfig()
    sim_user: SimUserConfig = SimUserConfig()
    eval: EvalConfig = EvalConfig()
    runtime: RuntimeConfig = RuntimeConfig()
    safety: SafetyConfig = SafetyConfig()
    arm: ArmConfig = ArmConfig()
    joystick: JoystickConfig = JoystickConfig()
    speech: SpeechConfig = SpeechConfig()
    voice: VoiceConfig = VoiceConfig()
    zmq: ZmqConfig = ZmqConfig()
    record: RecordConfig = RecordConfig()
    foxglove: FoxgloveConfig = FoxgloveConfig()
    web: WebConfig = WebConfig()
    asking: AskingConfig = AskingConfig()
    profiles: ProfilesConfig = ProfilesConfig()

    @model_validator(mode="after")
    def _check_method(self) -> Config:
        if self.method not in METHODS:
            raise ValueError(f"method: unknown method {self.method!r} (one of {', '.join(METHODS)})")
        if self.asking.third_answer and self.planner.model != "watch":
            raise ValueError("asking.third_answer: the planner plans the third answer with the watch model only "
                             '(planner.model = "watch")')
        if self.planner.model == "watch":  # its times are counted in rollout steps
            dt = self.planner.rollout_step_s
            for key, value in (("planner.horizon_s", self.planner.horizon_s), ("planner.watch_s", self.planner.watch_s),
                               ("reward.question_time_s", self.reward.question_time_s)):
                steps = value / dt
                if round(steps) < 1 or abs(steps - round(steps)) > 1e-9:
                    raise ValueError(f"{key}: {value:g} s is not a whole number of planner.rollout_step_s = {dt:g} s "
                                     "steps (at least one): the watch model counts it in rollout steps")
        return self


class ConfigError(ValueError):
    """A configuration problem; the message names the key (dotted path) and the file."""


MOVED = {"planner.user_standoff_m": "intent.user_standoff_m"}
"""Keys that moved, and where to: an old file's key is refused with the new place named."""


def _format(err: ValidationError, source: str) -> str:
    lines = []
    for e in err.errors():
        key = ".".join(str(p) for p in e["loc"]) or "(top level)"
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = f"unknown key (moved to {MOVED[key]})" if key in MOVED else "unknown key"
        elif e["type"] == "value_error":
            msg = msg.removeprefix("Value error, ")
        lines.append(f"{source}: {key}: {msg}")
    return "\n".join(lines)


def config_from_dict(data: dict[str, Any], source: str = "config") -> Config:
    """Validate a mapping into a :class:`Config`; raises :class:`ConfigError` naming each bad key."""
    try:
        return Config.model_validate(data)
    except ValidationError as e:
        raise ConfigError(_format(e, source)) from None


def load_config(path: str | Path | None = None) -> Config:
    """Load ``path`` (TOML) over the defaults; ``None`` gives the defaults."""
    if path is None:
        return Config()
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{p}: file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"{p}: cannot be read: {e}") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{p}: not valid TOML: {e}") from None
    return config_from_dict(data, str(p))
