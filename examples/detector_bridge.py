"""A detector bridge: turn a perception pipeline's detections and raw grasps (JSON) into ``set_scene``.

Written from ``docs/protocol.md`` and ``docs/scenes.md`` alone, like ``protocol_client.py``: it only
needs ``pyzmq``. Input (a file, or ``-`` for stdin), one detection per object, its raw grasp poses as a
grasp detector such as GPD gives them (no types: the daemon sorts them into the listed types with the
scene's classification rule), optionally in a marker's frame::

    {"marker_to_base": {"position": [0.1, 0.0, 0.0], "quat_wxyz": [1, 0, 0, 0]},
     "table_z": 0.0,
     "detections": [
       {"name": "mug", "shape": "cylinder", "size": [0.04, 0.10], "position": [0.42, 0.2, 0.05], "rim": true,
        "grasp_types": ["top_vertical", "side_horizontal"],
        "grasps": [{"position": [0.42, 0.2, 0.11], "quat_wxyz": [0, 1, 0, 0]}, ...]}]}

    python examples/detector_bridge.py detections.json --cmd tcp://127.0.0.1:5556 [--when next_task]

Prints the daemon's reply (the scene's targets, and goals dropped as unreachable with the reason);
exits 0 if the scene was taken, 1 if refused (the reason names the object and field), 2 if no daemon
answered.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import zmq

#: The keys of an object in the scene format that a detection may carry over.
OBJECT_KEYS = ("name", "shape", "size", "position", "yaw", "rim", "grasp_types", "grasps")


def set_scene_request(detections: dict[str, Any], when: str = "now", name: str = "detected") -> dict[str, Any]:
    """The ``set_scene`` request for ``detections`` (the module doc's format)."""
    objects = []
    for d in detections["detections"]:
        o = {k: d[k] for k in OBJECT_KEYS if k in d}
        o["grasps"] = [{"position": g["position"], "quat_wxyz": g["quat_wxyz"]} for g in d.get("grasps", [])]
        if not o["grasps"]:
            del o["grasps"]  # no detected grasps: the daemon generates them for the primitive
        objects.append(o)
    req: dict[str, Any] = {"cmd": "set_scene", "when": when,
                           "scene": {"name": name, "table_z": detections.get("table_z", 0.0), "objects": objects}}
    if detections.get("marker_to_base") is not None:
        req["marker_to_base"] = detections["marker_to_base"]
    return req


def send(endpoint: str, req: dict[str, Any], timeout_s: float) -> dict[str, Any] | None:
    ctx = zmq.Context.instance()
    s = ctx.socket(zmq.REQ)
    s.setsockopt(zmq.LINGER, 0)
    s.connect(endpoint)
    try:
        s.send(json.dumps(req).encode())
        if s.poll(int(timeout_s * 1000)):
            return json.loads(s.recv())
        return None
    finally:
        s.close(linger=0)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("file", help="detections JSON, or - for stdin")
    p.add_argument("--cmd", default="tcp://127.0.0.1:5556", help="the daemon's command endpoint")
    p.add_argument("--when", choices=("now", "next_task"), default="now")
    p.add_argument("--name", default="detected", help="the scene's name")
    p.add_argument("--timeout", type=float, default=5.0)
    a = p.parse_args(argv)
    detections = json.load(sys.stdin if a.file == "-" else open(a.file))  # noqa: SIM115
    reply = send(a.cmd, set_scene_request(detections, a.when, a.name), a.timeout)
    if reply is None:
        print(f"no reply from {a.cmd} within {a.timeout} s", file=sys.stderr)
        return 2
    print(json.dumps(reply))
    return 0 if reply.get("ok") else 1


if __name__ == "__main__":
    sys.exit(main())
