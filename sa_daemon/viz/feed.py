"""When each Foxglove message is sent: :class:`VizFeed` (``docs/foxglove.md``).

The daemon hands the feed what it already builds for its protocol (the ``scene`` reply, each
``state`` message at ``runtime.publish_hz``, each event); the feed turns them into messages
(:mod:`.messages`) and gives ``(topic, message, log_time_ns)`` to every sink: the live server
(:class:`~.live.LiveView`) and the MCAP recorder. The gripper and the belief go out with every
state; the table, objects and grasp poses (the bulk: one arrow per grasp pose) only when the scene
changes, when a target's probability has moved by more than ``belief_step`` since they were last
drawn (at most every ``min_redraw_s``), and at least every ``scene_period_s`` (a viewer that connects
late sees them within that). Drawing Scene 1's 54 grasp poses costs about 80 us (geometry computed once
per scene, :class:`~.messages.SceneDrawing`), the gripper about 30 us.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

from . import messages as fx

Sink = Callable[[str, Any, int], None]
"""A receiver of ``(topic, message, log_time_ns)``: a dict for ``/belief``, a Foxglove message otherwise."""


class VizFeed:
    """Foxglove messages from the daemon's protocol messages, rate-limited where they are bulky.

    Args:
        scene: the ``scene`` reply of ``docs/protocol.md`` (objects and every target's grasp poses).
        sinks: receivers of every message.
        scene_period_s: the scene entities are sent at least this often (s).
        belief_step: ... and whenever a target's probability has moved by more than this,
        min_redraw_s: ... but not more often than this (s).
        clock_ns: the messages' log time (default: wall clock, ns since the epoch, as the recorder).
    """

    def __init__(self, scene: Mapping[str, Any], sinks: list[Sink], scene_period_s: float = 1.0,
                 belief_step: float = 0.01, min_redraw_s: float = 0.2,
                 clock_ns: Callable[[], int] = time.time_ns) -> None:
        self._sinks = list(sinks)
        self._drawing = fx.SceneDrawing(scene)
        self._period_ns = int(scene_period_s * 1e9)
        self._step = belief_step
        self._min_ns = int(min_redraw_s * 1e9)
        self._clock = clock_ns
        self._drawn: dict[str, float] | None = None  # the belief the scene entities were last drawn with
        self._drawn_ns = 0
        self._replace = False
        self.sent = 0

    def _send(self, topic: str, msg: Any, t_ns: int) -> None:
        for sink in self._sinks:
            sink(topic, msg, t_ns)
        self.sent += 1

    def new_scene(self, scene: Mapping[str, Any]) -> None:
        """A ``set_scene`` changed the scene: the next state redraws everything, deleting the old entities."""
        self._drawing = fx.SceneDrawing(scene)
        self._drawn = None
        self._replace = True

    def state(self, state: Mapping[str, Any]) -> None:
        """One ``state`` message: the gripper and the belief, and the scene entities when due."""
        t_ns = self._clock()
        belief = {b["goal"]: float(b["p"]) for b in state.get("belief", [])}
        since = t_ns - self._drawn_ns
        due = (self._drawn is None or since >= self._period_ns
               or (since >= self._min_ns and any(abs(p - self._drawn.get(g, 0.0)) > self._step
                                                 for g, p in belief.items())))
        if due:
            self._send("/scene", self._drawing.update(belief, t_ns, replace=self._replace), t_ns)
            self._drawn, self._drawn_ns, self._replace = belief, t_ns, False
        self._send("/scene", fx.gripper_update(state, t_ns), t_ns)
        self._send("/belief", fx.belief_message(state), t_ns)

    def event(self, event: Mapping[str, Any]) -> None:
        """One event: a ``/log`` line (every kind but ``plan``)."""
        t_ns = self._clock()
        log = fx.event_log(event, t_ns)
        if log is not None:
            self._send("/log", log, t_ns)
