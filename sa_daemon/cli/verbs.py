"""The daemon's command-line verbs: ``run``, ``monitor``, ``answer``, ``keygen``, ``plot``, ``bench loop`` and ``bench soak``."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path
from typing import Any

from ..arm.backends import BACKENDS
from ..config import METHODS, Config, config_from_dict, load_config
from ..runtime.launch import DEFAULT_SCENE, DEFAULT_TASK, Launch
from ..world.scene import builtin_scene_names


def override(cfg: Config, updates: dict[str, Any]) -> Config:
    """``cfg`` with dotted keys replaced (``{"speech.wav_dir": "out"}``), validated again."""
    data = cfg.model_dump(mode="json")
    for key, value in updates.items():
        node = data
        *path, last = key.split(".")
        for p in path:
            node = node[p]
        node[last] = value
    return config_from_dict(data, "command line")


#: ``run`` flags that override a config key when given.
_FLAG_KEYS = {
    "arm": "arm.backend",
    "method": "method",
    "pub": "zmq.pub",
    "cmd": "zmq.cmd",
    "record": "record.path",
    "speech_wav": "speech.wav_dir",
    "foxglove_port": "foxglove.port",
}


def run_config(args: argparse.Namespace) -> Config:
    """The config file (``--config``) with ``run``'s flags over it."""
    cfg = load_config(args.config)
    updates: dict[str, Any] = {key: getattr(args, flag) for flag, key in _FLAG_KEYS.items()
                              if getattr(args, flag) is not None}
    if args.no_speech:
        updates["speech.enabled"] = False
    if args.foxglove:
        updates["foxglove.enabled"] = True
    return override(cfg, updates) if updates else cfg


def launch_of(args: argparse.Namespace, exit_when_done: bool | None = None) -> Launch:
    """``run``'s flags as a :class:`~.launch.Launch`."""
    return Launch(scene=args.scene_file or args.scene or DEFAULT_SCENE, tasks=tuple(args.task or ()),
                  input=args.input, duration_s=args.duration, seed=args.seed, progress=not args.quiet,
                  exit_when_done=exit_when_done, user=args.user or "calibrated", profile=args.profile)


def build_daemon(args: argparse.Namespace) -> Any:
    """The :class:`~.daemon.Daemon` that ``run`` would start (built by the composition root, ``launch.py``)."""
    from ..runtime.launch import build_daemon as build

    return build(run_config(args), launch_of(args))


def cmd_check(args: argparse.Namespace) -> int:
    """``run --arm xarm --check``: verify the real arm's controller without moving it (``arm/xarm_check.py``)."""
    from ..arm.xarm_check import format_check, run_check
    from ..config import ConfigError

    cfg = run_config(args)
    if cfg.arm.backend != "xarm":
        raise ConfigError(f"arm.backend: run --check checks the real arm's controller; use --arm xarm, not {cfg.arm.backend!r}")
    items = run_check(cfg)
    print(format_check(items))
    return 0 if all(i.ok for i in items) else 1


def cmd_run(args: argparse.Namespace) -> int:
    from ..runtime.rate import new_event_loop

    if args.check:
        return cmd_check(args)

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    daemon = build_daemon(args)
    loop = new_event_loop()
    try:
        code = loop.run_until_complete(daemon.run())
    finally:
        loop.close()
    figs = daemon.loop_figures()
    done = figs["tasks_done"]
    print(
        f"sa-daemon: ran {daemon.now():.1f} s | control {figs.get('rate_hz', 0):.1f} Hz, period error p99 "
        f"{figs.get('period_err_ms_p99', 0):.3f} ms | input->command p99 {figs['input_to_command_ms_p99']:.2f} ms | "
        f"{figs['plans']} plans, {figs['planner_restarts']} planner restarts | "
        + (", ".join(f"{d['task']} {'success' if d['success'] else 'failure'} in {d['time_s']:.1f} s" for d in done)
           or "no task finished"),
        file=sys.stderr,
    )
    if daemon.recorder is not None:
        print(f"sa-daemon: recording in {daemon.recorder.path} (sa-daemon plot {daemon.recorder.path})", file=sys.stderr)
    return code


def _command(args: argparse.Namespace, body: dict[str, Any]) -> int:
    """Send one protocol command to the running daemon, print its reply; exit 0 if it was applied, 1 if
    refused (a ``TimeoutError``, exit 2, when no daemon answers)."""
    from ..io.client import request
    from ..io.security import client_curve

    cfg = load_config(args.config)
    reply = request(args.cmd or cfg.zmq.cmd, body, timeout_s=args.timeout, curve=client_curve(cfg.zmq))
    print(json.dumps(reply))
    return 0 if reply.get("ok") else 1


def cmd_answer(args: argparse.Namespace) -> int:
    return _command(args, {"cmd": "answer", "value": args.value})


def cmd_scene_push(args: argparse.Namespace) -> int:
    """Send a scene file (TOML or JSON, ``docs/scenes.md``) to the running daemon as ``set_scene``."""
    import tomllib

    from ..config import ConfigError

    path = Path(args.file)
    try:
        text = path.read_text()
        data = json.loads(text) if path.suffix == ".json" else tomllib.loads(text)
    except (OSError, ValueError) as e:
        raise ConfigError(f"scene push: {path}: {e}") from None
    body: dict[str, Any] = {"cmd": "set_scene", "scene": data, "when": args.when}
    if args.marker_to_base:
        pose = json.loads(args.marker_to_base)
        body["marker_to_base"] = pose
    return _command(args, body)


def cmd_stop(args: argparse.Namespace) -> int:
    return _command(args, {"cmd": "stop"})


def cmd_resume(args: argparse.Namespace) -> int:
    return _command(args, {"cmd": "resume"})


def cmd_monitor(args: argparse.Namespace) -> int:
    from ..io.security import client_curve
    from .monitor import monitor

    cfg = load_config(args.config)
    curve = client_curve(cfg.zmq) if cfg.zmq.curve_pub else None
    return monitor(args.pub or cfg.zmq.pub, duration_s=args.duration, once=args.once, curve=curve)


def cmd_web(args: argparse.Namespace) -> int:
    """Serve the page (``sa_daemon/web``) for the daemon at ``--pub``/``--cmd`` until SIGINT/SIGTERM."""
    from ..io.security import client_curve
    from ..web.server import run_web

    cfg = load_config(args.config)
    web = cfg.web.model_copy(update={"listen": args.listen}) if args.listen else cfg.web
    run_web(web, args.pub or cfg.zmq.pub, args.cmd or cfg.zmq.cmd, client_curve(cfg.zmq))
    return 0


def cmd_calibrate(args: argparse.Namespace) -> int:
    """Measure a person's stick (``io/calibrate.py``) and write it into their profile."""
    import asyncio
    import tomllib

    import evdev

    from ..config import ConfigError
    from ..io.calibrate import CalibrationError, calibrate
    from ..profile import Profile, parse_profile, profile_toml, resolve

    cfg = load_config(args.config)
    path = resolve(args.profile, cfg.profiles.dir)
    device = None
    for p in evdev.list_devices():
        dev = evdev.InputDevice(p)
        if args.device in (p, dev.name):
            device = dev
            break
        dev.close()
    if device is None:
        raise ConfigError(f"calibrate --device: no input device {args.device!r} (evdev.list_devices)")
    print(f"calibrating {device.name} ({device.path}), axes {', '.join(cfg.joystick.axes)}")
    try:
        result = asyncio.run(calibrate(device, cfg.joystick, args.rest, args.move))
    except CalibrationError as e:
        print(f"calibrate: {e}", file=sys.stderr)
        return 1
    finally:
        device.close()
    print(result.report())
    old = parse_profile(tomllib.loads(path.read_text()), str(path)) if path.exists() else Profile(path.stem)
    joystick = {**old.overrides.get("joystick", {}), **result.joystick_keys()}
    new = Profile(old.name, old.summary, {**old.overrides, "joystick": joystick}, str(path))
    new.apply(cfg)  # checked like any profile before it is written
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(profile_toml(new))
    print(f"wrote {path} ([joystick] {', '.join(result.joystick_keys())}); use it with run --profile {args.profile}")
    return 0


def cmd_keygen(args: argparse.Namespace) -> int:
    """Write CURVE keys (``sa_daemon.io.keygen``) and print the config lines that use them."""
    from ..io.keygen import generate, write_web_token

    if args.web_token:
        path, written = write_web_token(args.dir, force=args.force)
        print(f"web token {'written' if written else 'kept'}: {path} (secret, 0600)")
        print(f"\n# sa-daemon web's config.toml (the page may now listen beyond loopback, with TLS)\n[web]\n"
              f"token_file = {json.dumps(str(path))}\n# open https://HOST:PORT/?token=<the file's text> once on "
              "the tablet; the page keeps it in a cookie")
        if args.client is None and args.clients is None:
            return 0
    if args.clients is not None and args.clients < 0:
        raise ValueError("keygen --clients: must be 0 or more")
    names = list(args.client or [])
    names += [f"client{i}" for i in range(1, (args.clients or 0) + 1)]
    if args.client is None and args.clients is None:
        names = ["client1"]
    res = generate(args.dir, names, force=args.force)
    q = json.dumps  # a JSON string of a path is a valid TOML string
    print(f"server key pair {'written' if res.server_created else 'kept'}: {res.server_public} (public), "
          f"{res.server_secret} (secret, 0600)")
    for name, secret in res.clients.items():
        print(f"client {name}: {secret} (secret, 0600); public key allowed as {res.allowed_dir / (name + '.key')}")
    print("\n# the daemon's config.toml (CURVE on: zmq.cmd may now be e.g. tcp://0.0.0.0:5556)")
    print(f"[zmq]\ncurve_server_secret = {q(str(res.server_secret))}\ncurve_clients_dir = {q(str(res.allowed_dir))}")
    for name, secret in res.clients.items():
        print(f"\n# config.toml of client {name} (sa-daemon answer/monitor; copy its .key_secret to it, nothing else)")
        print(f"[zmq]\ncurve_client_secret = {q(str(secret))}\ncurve_server_public = {q(str(res.server_public))}")
    print("\n# revoke a client: delete its allowed_clients/NAME.key and restart the daemon")
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from ..runtime.replay import recording_to_trial
    from ..sim.plots import plot_timeline

    trial = recording_to_trial(args.recording)
    out = Path(args.out) if args.out else Path(args.recording).with_suffix(".png")
    plot_timeline(trial, out)
    print(f"wrote {out} ({len(trial.timeline.t) if trial.timeline else 0} states)")
    return 0


def _write_figures(path: str | None, figs: dict[str, Any]) -> None:
    if path:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(figs, indent=2) + "\n")
        print(f"wrote {path}")


def cmd_bench_loop(args: argparse.Namespace) -> int:
    from ..bench.loop import format_loop, run_loop_bench

    figs = run_loop_bench(run_config(args), launch_of(args, exit_when_done=False), args.subscribers,
                          args.stalled_subscribers)
    print(format_loop(figs))
    _write_figures(args.json, figs)
    return 0


def cmd_bench_soak(args: argparse.Namespace) -> int:
    """Exit 0 when every soak criterion passes, 1 when one fails."""
    from ..bench.soak import SoakSpec, format_soak, run_soak

    spec = SoakSpec(args.duration, args.sample_every, args.max_growth_pct, args.max_overruns, args.platform_probe)
    figs = run_soak(run_config(args), launch_of(args, exit_when_done=False), spec, args.subscribers,
                    args.stalled_subscribers)
    print(format_soak(figs))
    _write_figures(args.json, figs)
    return 0 if figs["pass"] else 1


def add_run_options(p: argparse.ArgumentParser) -> None:
    """The flags of ``run`` (shared with ``bench loop``)."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--scene", help=f"built-in scene ({', '.join(builtin_scene_names())}; default {DEFAULT_SCENE})")
    g.add_argument("--scene-file", help="scene TOML file (docs/scenes.md)")
    p.add_argument("--arm", choices=BACKENDS, help="arm backend (default: config arm.backend)")
    p.add_argument("--input", choices=["sim", "evdev"], default="sim", help="joystick or simulated user")
    p.add_argument("--task", action="append", help=f"sim user's task object:grasp_type, repeatable (default {DEFAULT_TASK})")
    p.add_argument("--method", choices=METHODS, help="assistance method (default: config method)")
    p.add_argument("--pub", help="PUB endpoint (default: config zmq.pub)")
    p.add_argument("--cmd", help="command endpoint (default: config zmq.cmd)")
    p.add_argument("--record", help="MCAP file to record to ({time} = timestamp)")
    p.add_argument("--foxglove", action="store_true", help="serve the live view to Foxglove on 127.0.0.1 "
                   "(docs/foxglove.md; config foxglove.enabled)")
    p.add_argument("--foxglove-port", type=int, help="its port (default: config foxglove.port, 8765)")
    p.add_argument("--speech-wav", help="also write every spoken question as a WAV file in this folder")
    p.add_argument("--no-speech", action="store_true", help="publish questions without speaking them")
    p.add_argument("--seed", type=int, default=0, help="simulated user's random seed")
    p.add_argument("--user", metavar="NAME|FILE", help="simulated user profile (docs/simulated-user.md; default calibrated)")
    p.add_argument("--profile", metavar="NAME|FILE", help="the person's profile: NAME.toml in profiles.dir, or a "
                   "file (docs/profiles.md)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def add_parsers(sub: Any) -> None:
    """Register the daemon verbs on the ``sa-daemon`` sub-parser."""
    r = sub.add_parser("run", help="run the daemon (arm, input, planner, speech, ZeroMQ)")
    add_run_options(r)
    r.add_argument("--duration", type=float, help="stop cleanly after this many seconds (default: with "
                   "the sim user, when its tasks are done; with a joystick, never)")
    r.add_argument("--check", action="store_true", help="with --arm xarm: connect, set or verify the controller's "
                   "limits, print a pass/fail list and exit, without moving the arm (docs/xarm.md)")
    r.set_defaults(func=cmd_run)

    m = sub.add_parser("monitor", help="live view of a running daemon (over ZeroMQ)")
    m.add_argument("--pub", help="PUB endpoint (default: config zmq.pub)")
    m.add_argument("--duration", type=float, help="stop after this many seconds")
    m.add_argument("--once", action="store_true", help="print one state and exit")
    m.set_defaults(func=cmd_monitor)

    a = sub.add_parser("answer", help="answer the pending question")
    a.add_argument("value", choices=["yes", "no"])
    w = sub.add_parser("web", help="the page for the carer and the researcher: belief, question, Stop (docs/web.md)")
    w.add_argument("--listen", help="HOST:PORT (default: config web.listen, 127.0.0.1:8080)")
    w.add_argument("--pub", help="the daemon's PUB endpoint (default: config zmq.pub)")
    w.add_argument("--cmd", help="the daemon's command endpoint (default: config zmq.cmd)")
    w.set_defaults(func=cmd_web)

    sc = sub.add_parser("scene", help="live scenes: push a scene to the running daemon (set_scene)")
    scsub = sc.add_subparsers(dest="scene_verb", required=True)
    push = scsub.add_parser("push", help="send a scene file (TOML or JSON, docs/scenes.md) as set_scene")
    push.add_argument("file")
    push.add_argument("--when", choices=("now", "next_task"), default="now",
                      help="now (the arm must be stopped) or at the simulated user's next task")
    push.add_argument("--marker-to-base", metavar="JSON", help='the scene is in a marker frame: '
                      '\'{"position": [x, y, z], "quat_wxyz": [w, x, y, z]}\' maps it to the base frame')
    push.add_argument("--cmd", help="command endpoint (default: config zmq.cmd)")
    push.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the reply")
    push.set_defaults(func=cmd_scene_push)

    sub.add_parser("stop", help="latch the running daemon's stop (the arm is commanded zero)").set_defaults(
        func=cmd_stop)
    sub.add_parser("resume", help="release the stop and clear an arm fault (after a stop, passes the start-up "
                   "stop self-test)").set_defaults(func=cmd_resume)
    for c in (a, sub.choices["stop"], sub.choices["resume"]):
        c.add_argument("--cmd", help="command endpoint (default: config zmq.cmd)")
        c.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for the reply")
    a.set_defaults(func=cmd_answer)

    c = sub.add_parser("calibrate", help="measure a person's joystick (rest, range, noise) into their profile")
    c.add_argument("--device", required=True, help="/dev/input/eventN or the device's name")
    c.add_argument("--profile", required=True, metavar="NAME|FILE", help="the profile to write (created or updated)")
    c.add_argument("--rest", type=float, default=3.0, help="seconds the stick is left at rest")
    c.add_argument("--move", type=float, default=8.0, help="seconds the stick is moved to its limits")
    c.set_defaults(func=cmd_calibrate)

    k = sub.add_parser("keygen", help="write CURVE keys for a daemon exposed beyond loopback, print the config")
    k.add_argument("dir", help="key directory (created; e.g. /etc/sa-daemon/curve)")
    k.add_argument("--client", action="append", metavar="NAME", help="a client key pair named NAME (repeatable)")
    k.add_argument("--clients", type=int, metavar="N", help="N client key pairs named client1..clientN (default: 1 unless --client)")
    k.add_argument("--force", action="store_true", help="replace existing keys (a new server key invalidates "
                   "every client's curve_server_public)")
    k.add_argument("--web-token", action="store_true", help="write DIR/web.token, the access token of sa-daemon web "
                   "(only that, unless --client/--clients are given too)")
    k.set_defaults(func=cmd_keygen)

    pl = sub.add_parser("plot", help="Fig. 4 timeline of a recording (MCAP)")
    pl.add_argument("recording")
    pl.add_argument("--out", help="PNG path (default: next to the recording)")
    pl.set_defaults(func=cmd_plot)


def _add_bench_options(p: argparse.ArgumentParser, duration_s: float) -> None:
    """``run``'s flags plus what ``bench loop`` and ``bench soak`` share: duration, JSON, subscriber load."""
    add_run_options(p)
    p.add_argument("--duration", type=float, default=duration_s, help=f"seconds to run (default {duration_s:g})")
    p.add_argument("--json", help="write the figures to this file")
    p.add_argument("--subscribers", type=int, default=0, metavar="N",
                   help="N subscribers in another process that read every message (default 0)")
    p.add_argument("--stalled-subscribers", type=int, default=0, metavar="M",
                   help="M subscribers in that process that connect and never read (default 0)")


def add_bench_parsers(bsub: Any) -> None:
    bl = bsub.add_parser("loop", help="daemon loop rates, jitter, latency and memory with the sim user")
    _add_bench_options(bl, 30.0)
    bl.set_defaults(func=cmd_bench_loop)

    bs = bsub.add_parser("soak", help="long run with the sim user: RSS growth, overruns, restarts "
                         "(exit 1 if a criterion fails)")
    _add_bench_options(bs, 600.0)
    bs.add_argument("--sample-every", type=float, default=5.0, help="RSS sampling period, s (default 5)")
    bs.add_argument("--max-growth-pct", type=float, default=5.0,
                    help="RSS growth after warm-up allowed for the daemon and the worker, %% (default 5)")
    bs.add_argument("--max-overruns", type=int, default=0, help="control overruns allowed (default 0)")
    bs.add_argument("--no-platform-probe", dest="platform_probe", action="store_false",
                    help="do not run cyclictest beside the daemon (default: run it when installed)")
    bs.set_defaults(func=cmd_bench_soak)
