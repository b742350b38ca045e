"""The simulated xArm-6 in MuJoCo (``--arm mujoco``): real contact physics for the gripper and objects.

Twist to joints. ``command_twist`` holds a base-frame twist (m/s, rad/s; per-axis limited by
``cfg.limits``). Every physics substep the driver solves the joint velocities for that twist with
Pinocchio (:meth:`ArmKinematics.joint_velocities`: damped least squares, joint-margin locking, joint
speed scaling) at the servo reference ``q_ref``, integrates ``q_ref += qdot * timestep`` and sends both
to the joint servos of ``xarm6.xml``: ``tau = kp (q_ref - q) + kv (qdot - qdot_measured)`` with gravity
compensated by MuJoCo's ``gravcomp``. Solving at ``q_ref`` (which the measured ``q`` follows within about
1e-4 rad in free motion) makes the reference TCP follow the twist like the kinematic arm does; solving
every substep (not once per ``step`` call) keeps long calls such as ``step(1.0)`` exact. The reference is
kept within ``MAX_LAG_RAD`` of the measured joints, so an arm blocked by contact does not wind up.

Gripper. ``command_gripper(True)`` drives both fingers (coupled, position servo, at most 40 N) closed.
The arm keeps obeying ``command_twist`` (it carries what it holds, as the xArm does); the safety
pipeline holds it still while the gripper is closed.
:meth:`MujocoArm.lift_test` then lifts the TCP and reports which object rose with it.

Headless by default. With ``viewer`` a passive viewer window follows the simulation if a display
exists; :meth:`MujocoArm.render` writes offscreen PNG frames (``MUJOCO_GL=egl`` on headless machines).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any

from .mujoco_render import has_display, prefer_headless_gl, write_png

prefer_headless_gl()  # before the first ``import mujoco``: the GL backend is chosen on import

import mujoco
import numpy as np

from ..config import Config
from ..geometry import FloatArray, Pose
from ..world.scene import Scene
from .base import Arm, ArmState, commanded_twist
from .kinematics import (
    ARM_JOINTS,
    FINGER_JOINTS,
    TCP_FRAME,
    ArmKinematics,
    start_configuration,
)
from .mujoco_scene import build_scene_model, object_heights

FINGER_OPEN_M = 0.0425
"""Half opening (m) of the open gripper: the xArm gripper's 0.085 m stroke."""
FINGER_CLOSED_CMD_M = -0.01
"""Gripper servo target when closed (m): past the fingers' stop, so the servo squeezes at its 40 N limit."""
MAX_LAG_RAD = 0.02
"""Largest allowed servo reference lead over the measured joint position (rad), against wind-up."""
START_TOL_M = 1e-3
"""The start configuration must put the TCP within this (m) of ``scene.start``."""


class MujocoArm(Arm):
    """xArm-6 + gripper + table + the scene's objects, stepped in simulated time.

    ``scene`` gives the objects and the start pose, ``cfg`` the time step and viewer
    (``cfg.arm.mujoco``), the Cartesian speed limits (``cfg.limits``) and the joint margin
    (``cfg.safety.joint_margin_rad``). ``viewer`` overrides ``cfg.arm.mujoco.viewer``.
    """

    name = "mujoco"

    @classmethod
    def from_config(cls, scene: Scene, cfg: Config) -> MujocoArm:
        return cls(scene, cfg)

    def __init__(self, scene: Scene, cfg: Config | None = None, *, viewer: bool | None = None) -> None:
        cfg = cfg or Config()
        self._limits = cfg.limits
        self.kinematics = ArmKinematics(joint_margin=cfg.safety.joint_margin_rad)
        self.world = build_scene_model(scene, cfg.arm.mujoco.timestep_s)
        self.table_z = scene.table_z  # m, base frame
        self.model = self.world.model
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._qadr = np.array([m.joint(j).qposadr[0] for j in ARM_JOINTS])
        self._vadr = np.array([m.joint(j).dofadr[0] for j in ARM_JOINTS])
        self._fadr = np.array([m.joint(j).qposadr[0] for j in FINGER_JOINTS])
        self._fvadr = np.array([m.joint(j).dofadr[0] for j in FINGER_JOINTS])
        self._pos_act = np.array([m.actuator(f"pos{i}").id for i in range(1, 7)])
        self._vel_act = np.array([m.actuator(f"vel{i}").id for i in range(1, 7)])
        self._grip_act = m.actuator("gripper").id
        self._tcp = m.site(TCP_FRAME).id
        self._ts = float(m.opt.timestep)
        self._twist = np.zeros(6)
        self._closed = False
        self._viewer = None
        self._renderer: mujoco.Renderer | None = None
        self._frame = 0
        q0 = start_configuration(self.kinematics, scene.start)
        self._q0 = q0
        self._place_joints(q0)
        d_t, d_r = self.read().pose.distance(scene.start)
        if d_t > START_TOL_M or d_r > START_TOL_M:
            raise RuntimeError(f"start configuration misses {scene.name}'s start pose by {d_t * 1e3:.2f} mm, {d_r:.4f} rad")
        if viewer if viewer is not None else cfg.arm.mujoco.viewer:
            self._open_viewer()

    # -- state ---------------------------------------------------------------------------------------

    @property
    def q(self) -> FloatArray:
        """Measured arm joint positions (rad)."""
        return self.data.qpos[self._qadr].copy()

    @property
    def fingers(self) -> FloatArray:
        """Finger slide positions (m): half openings of the left and right finger, 0 = closed."""
        return self.data.qpos[self._fadr].copy()

    @property
    def time(self) -> float:
        """Simulated time (s) since the start."""
        return float(self.data.time)

    def read(self) -> ArmState:
        """TCP pose of the ``tcp`` site (base frame), gripper state and joints (rad)."""
        p = self.data.site_xpos[self._tcp].copy()
        r = self.data.site_xmat[self._tcp].reshape(3, 3)
        return ArmState(Pose.from_matrix(p, r), self._closed, None, self.q)

    def status(self) -> dict[str, Any]:
        """Diagnostics: simulated time (s), finger half openings (m), contact count, viewer open."""
        return {
            "sim_time_s": round(self.time, 6),
            "fingers_m": [round(float(f), 5) for f in self.fingers],
            "contacts": int(self.data.ncon),
            "viewer": self._viewer is not None,
        }

    # -- commands ------------------------------------------------------------------------------------

    def command_twist(self, twist: FloatArray) -> None:
        """Hold ``twist`` (m/s, rad/s, base frame) until the next command (a closed gripper does not gate
        it: see :meth:`command_gripper`)."""
        self._twist = commanded_twist(twist, self._limits)

    def command_gripper(self, closed: bool) -> None:
        """Close (``True``: fingers driven shut) or open the gripper. Motion is not gated here: like the
        xArm, the arm carries what it holds; holding it still while the gripper is closed is the safety
        pipeline's stage (``gripper_closed``)."""
        self._closed = bool(closed)
        self.data.ctrl[self._grip_act] = FINGER_CLOSED_CMD_M if self._closed else FINGER_OPEN_M

    def step(self, dt: float) -> None:
        """Advance the simulation by ``dt`` s under the held twist.

        Runs as many ``timestep`` substeps as keep the simulated clock on the caller's clock:
        ``ceil(dt / timestep)`` when ``dt`` is a multiple of the step (10 ms: 5 steps of 2 ms), and for
        other ``dt`` (25 ms) alternately 12 and 13 so time never drifts. Joint velocities are re-solved
        every substep.
        """
        if not (math.isfinite(dt) and dt >= 0.0):
            raise ValueError(f"dt must be a finite, non-negative number of seconds, got {dt}")
        n = math.floor((self._clock + dt - self.data.time) / self._ts + 0.5)
        self._clock += dt
        for _ in range(max(n, 0)):
            self._substep()
        mujoco.mj_kinematics(self.model, self.data)  # read() sees the state after the last substep
        if self._viewer is not None and self._viewer.is_running():
            self._viewer.sync()

    def _substep(self) -> None:
        qdot = np.zeros(6)
        if np.any(self._twist):
            qdot = self.kinematics.joint_velocities(self._qref, self._twist)
            self._qref = np.clip(self._qref + qdot * self._ts, self.kinematics.lower, self.kinematics.upper)
        q = self.data.qpos[self._qadr]
        self._qref = np.clip(self._qref, q - MAX_LAG_RAD, q + MAX_LAG_RAD)
        self.data.ctrl[self._pos_act] = self._qref
        self.data.ctrl[self._vel_act] = qdot
        mujoco.mj_step(self.model, self.data)

    def _place_joints(self, q: FloatArray) -> None:
        """Put the arm at ``q`` (rad) at rest with open fingers, servos holding it there."""
        d = self.data
        d.qpos[self._qadr] = q
        d.qvel[self._vadr] = 0.0
        d.qpos[self._fadr] = FINGER_OPEN_M if not self._closed else d.qpos[self._fadr]
        d.qvel[self._fvadr] = 0.0
        d.ctrl[self._grip_act] = FINGER_CLOSED_CMD_M if self._closed else FINGER_OPEN_M
        self._qref = np.array(q, dtype=float)
        d.ctrl[self._pos_act] = self._qref
        d.ctrl[self._vel_act] = 0.0
        self._clock = float(d.time)
        mujoco.mj_forward(self.model, d)

    def reset(self) -> bool:
        """Back to the state of a fresh arm: the model's initial state (objects where the scene puts
        them, clock at 0), then the arm at its start configuration, fingers open. No recompilation."""
        mujoco.mj_resetData(self.model, self.data)
        self._twist = np.zeros(6)
        self._closed = False
        self._place_joints(self._q0)
        return True

    def place(self, pose: Pose) -> FloatArray:
        """Teleport the TCP to ``pose`` (IK from the current joints), at rest; returns the joints (rad).

        For tests and demos (e.g. put the open gripper round an object); objects are not moved, so the
        caller must choose a pose where the gripper does not overlap them.
        """
        q = self.kinematics.ik(pose, self.q)
        self._twist = np.zeros(6)
        self._place_joints(q)
        return q

    # -- physical success check ----------------------------------------------------------------------

    def lift_test(self, height: float = 0.05, speed: float = 0.05, settle_s: float = 1.0) -> str | None:
        """Stop the arm, close the gripper (if open), let the fingers settle, lift the TCP by ``height`` m
        at ``speed`` m/s, hold 0.3 s, and return the name of the object that rose by at least half of
        ``height`` (the one that rose most), or ``None``. Moves the arm: call it when the trial is over.

        The arm stands still from the call until the lift, whatever twist it last held: the fingers close
        where the trial closed them, as the safety pipeline's ``gripper_closed`` stage holds the arm in the
        daemon (a trial ends at the close without a further command).
        """
        self._twist = np.zeros(6)
        if not self._closed:
            self.command_gripper(True)
        waited = 0.0
        while waited < settle_s:
            self.step(0.05)
            waited += 0.05
            if waited >= 0.2 and float(np.max(np.abs(self.data.qvel[self._fvadr]))) < 1e-3:
                break
        before = object_heights(self.world, self.data)
        self._twist = np.array([0.0, 0.0, speed, 0.0, 0.0, 0.0])
        self.step(height / speed)
        self._twist = np.zeros(6)
        self.step(0.3)
        rise = object_heights(self.world, self.data) - before
        i = int(np.argmax(rise))
        return self.world.object_names[i] if rise[i] >= 0.5 * height else None

    # -- viewing -------------------------------------------------------------------------------------

    def _open_viewer(self) -> None:
        if not has_display():
            warnings.warn("MuJoCo viewer requested but no display (DISPLAY/WAYLAND_DISPLAY) exists: running "
                          "headless; use render() for images", RuntimeWarning, stacklevel=3)
            return
        import mujoco.viewer

        self._viewer = mujoco.viewer.launch_passive(self.model, self.data)

    def render(self, path_or_dir: str | Path, width: int = 640, height: int = 480,
               camera: mujoco.MjvCamera | str | None = None) -> Path:
        """Render the current state offscreen to a PNG; returns its path.

        ``path_or_dir``: a ``.png`` file, or a directory that receives ``frame_00000.png``,
        ``frame_00001.png``, ... on successive calls. ``camera``: a named model camera, an
        ``MjvCamera``, or ``None`` for a view of the arm and table from the front left. Needs an
        offscreen GL backend (``MUJOCO_GL=egl`` or ``osmesa`` set before ``mujoco`` is imported);
        raises ``RuntimeError`` naming the backend otherwise.
        """
        target = Path(path_or_dir)
        if target.suffix.lower() != ".png":
            target = target / f"frame_{self._frame:05d}.png"
            self._frame += 1
        if camera is None:
            camera = mujoco.MjvCamera()
            camera.lookat[:] = (0.3, 0.0, self.table_z + 0.12)
            camera.distance, camera.azimuth, camera.elevation = 1.4, -140.0, -25.0
        try:
            if self._renderer is None or (self._renderer.width, self._renderer.height) != (width, height):
                if self._renderer is not None:
                    self._renderer.close()
                self._renderer = mujoco.Renderer(self.model, height, width)
            self._renderer.update_scene(self.data, camera=camera)
            img = self._renderer.render()
        except Exception as e:  # GL backends fail with many exception types
            import os

            self._renderer = None
            raise RuntimeError(
                f"offscreen rendering failed with MUJOCO_GL={os.environ.get('MUJOCO_GL', '')!r} ({e}); set "
                "MUJOCO_GL=egl or MUJOCO_GL=osmesa before importing mujoco"
            ) from e
        return write_png(target, img)

    def close(self) -> None:
        """Release the viewer and the renderer (idempotent)."""
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
