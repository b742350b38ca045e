"""Turn an MCAP recording of the daemon into the evaluation's trial record, for ``sa-daemon plot``."""

from __future__ import annotations

from pathlib import Path

from ..io.recorder import read_recording
from ..sim.episode import Timeline, TrialResult


def recording_to_trial(path: str | Path) -> TrialResult:
    """The recorded states as a :class:`TrialResult` with its timeline (the first task's metadata).

    ``ValueError`` if the file holds no state.
    """
    tl = Timeline()
    targets: list[str] = []
    task, method, scene, success = "", "", "", False
    for topic, _, msg in read_recording(path):
        if topic == "/event":
            kind = msg.get("type")
            if kind == "task" and not task:
                task = str(msg.get("task", ""))
            elif kind == "ready":
                method = str(msg.get("method", ""))
                scene = str(msg.get("scene", scene))
            elif kind == "task_done" and msg.get("task") == task:
                success = bool(msg.get("success"))
            continue
        if topic != "/state":
            continue
        belief = msg["belief"]
        if not targets:
            targets = list(belief)
        tl.t.append(float(msg["t"]))
        tl.belief.append([float(belief.get(g, 0.0)) for g in targets])
        tl.action.append(str(msg["action"]))
        tl.opposed.append(bool(msg.get("opposed", False)))
        tl.user_twist.append(list(msg["user_twist"]))
        tl.robot_twist.append(list(msg["robot_twist"]))
        tl.command_twist.append(list(msg["command_twist"]))
        tl.safety.append(str(msg.get("safety", "ok")))
        tl.mode.append(str(msg["mode"]))
    if not tl.t:
        raise ValueError(f"{path}: no recorded state")
    return TrialResult(
        scene=scene or Path(path).stem, task=task, method=method, seed=0, success=success,
        completion_time_s=tl.t[-1] - tl.t[0], mode_changes=0, joystick_input=0.0, opposing_pct=0.0,
        correct_prediction=False, questions=0, final_target_p=0.0, plans=0, targets=targets, timeline=tl,
    )
