"""The ``sa-daemon`` command line: the parser, ``main``, and the verbs that are not the daemon's
(``eval``, ``bench planner``, ``bench voice``, ``hear``, ``scenes``); ``verbs.py`` holds the daemon's."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..arm.backends import SIMULATED_BACKENDS
from ..config import METHODS, Config, ConfigError, load_config
from ..cores import cores
from ..extras import MissingExtra
from ..sim.suites import SUITES
from ..sim.users import builtin_user_names
from ..world.goals import parse_target
from ..world.scene import SceneError, builtin_scene_names, load_scene
from . import verbs


def _scene_arg(args: argparse.Namespace) -> str:
    return args.scene_file or args.scene


def _add_scene(p: argparse.ArgumentParser, required: bool = True) -> None:
    g = p.add_mutually_exclusive_group(required=required)
    g.add_argument("--scene", help=f"built-in scene ({', '.join(builtin_scene_names())})")
    g.add_argument("--scene-file", help="scene TOML file (docs/scenes.md)")


def cmd_eval(args: argparse.Namespace) -> int:
    from ..sim.evaluate import (
        TrialSpec,
        compare,
        earlier_trials,
        format_summary,
        rule_line,
        run_trials,
        summarise,
        write_results,
    )
    from ..sim.suites import SuitePart, suite
    from ..sim.users import CALIBRATED, load_user

    cfg = load_config(args.config)
    users = args.user or [CALIBRATED]
    for u in users:
        load_user(u).apply(cfg)  # a bad profile is refused (exit 2) before anything runs
    if args.suite:
        s = suite(args.suite)
        parts = [SuitePart(p.scene, tuple(args.task or p.tasks), tuple(args.method or p.methods)) for p in s.parts]
    else:
        if not _scene_arg(args):
            raise ConfigError("eval: give --scene, --scene-file or --suite")
        scene = load_scene(_scene_arg(args))
        parts = [SuitePart(_scene_arg(args), tuple(args.task or scene.targets), tuple(args.method or METHODS))]
    for part in parts:
        scene = load_scene(part.scene)
        for t in part.tasks:
            parse_target(t)
            scene.goal(t)
    seeds = args.seeds or (suite(args.suite).seeds if args.suite else 5)
    if args.first_seed < 0:
        raise ConfigError("eval: --first-seed must be >= 0")
    specs = [TrialSpec(p.scene, t, m, seed, u) for p in parts for t in p.tasks for u in users for m in p.methods
             for seed in range(args.first_seed, args.first_seed + seeds)]
    earlier = earlier_trials(args.merge or [], cfg, args.arm, specs)
    plots = Path(args.plots) if args.plots else None
    trials = run_trials(specs, cfg, jobs=args.jobs, progress=not args.quiet, plots=plots, arm=args.arm,
                        backend=args.backend, address=args.address)
    speed = trials.speed
    trials = earlier + list(trials)
    summary = summarise(trials)
    comparisons = compare(trials)
    print(format_summary(summary, comparisons=comparisons))
    print("stars: policy differs from that method on that metric (paired Wilcoxon over seeds, Holm per task"
          " and user: * p<0.05 ** p<0.01 *** p<0.001 **** p<0.0001)")
    if (line := rule_line(summary)) is not None:
        print(line)
    if speed is not None:
        print(speed.line())
    if plots is not None:
        from ..sim.plots import plot_summary_bars

        for part in parts:
            name = load_scene(part.scene).name
            rows = [r for r in summary if r["scene"] == name]
            bars = plot_summary_bars(rows, plots / f"summary_{name.replace(' ', '-')}.png", title=name,
                                     comparisons=comparisons)
            print(f"wrote {bars}")
        print(f"wrote {len(trials)} timelines to {plots}")
    if args.json:
        meta = {"suite": args.suite, "scenes": [load_scene(p.scene).name for p in parts],
                "parts": [{"scene": p.scene, "tasks": list(p.tasks), "methods": list(p.methods)} for p in parts],
                "users": list(dict.fromkeys([*(t["user"] for t in earlier), *users])),
                "seeds": len({t["seed"] for t in trials}), "arm": args.arm, "config": cfg.model_dump(mode="json")}
        if args.merge:
            meta["merged"] = list(args.merge)
        if len(parts) == 1:  # the single-scene keys older files have (docs/results/rerun.py reads either)
            meta.update(scene=meta["scenes"][0], tasks=list(parts[0].tasks), methods=list(parts[0].methods))
        write_results(args.json, trials, summary, meta, comparisons)
        print(f"wrote {args.json}")
    return 0


def cmd_bench_planner(args: argparse.Namespace) -> int:
    from ..bench.planner import format_table, run_planner_bench, write_json

    cfg = load_config(args.config)
    r = run_planner_bench(load_scene(_scene_arg(args)), cfg, args.samples, args.budget, peer=not args.no_peer)
    print(format_table(r))
    if args.json:
        write_json(r, args.json)
        print(f"wrote {args.json}")
    return 0


def _voice_args(args: argparse.Namespace) -> tuple[Config, float]:
    """The voice extra present (else one line naming it), the config, and ``--min-confidence`` over
    ``voice.min_confidence``."""
    from ..extras import require

    require("pocketsphinx", "voice")
    cfg = load_config(args.config)
    return cfg, cfg.voice.min_confidence if args.min_confidence is None else args.min_confidence


def cmd_bench_voice(args: argparse.Namespace) -> int:
    from ..bench.voice import format_table, run_voice_bench, write_json

    _, threshold = _voice_args(args)
    r = run_voice_bench(threshold, jobs=args.jobs, third=args.third_answer)
    print(format_table(r))
    if args.json:
        write_json(r, args.json)
        print(f"wrote {args.json}")
    return 0


def cmd_hear(args: argparse.Namespace) -> int:
    """One word (yes, no, none; other with asking.third_answer) for a WAV file, with the confidence: the
    recogniser on your voice."""
    cfg, threshold = _voice_args(args)
    from ..speech.audio import answer_in, wav_to_16k
    from ..speech.recogniser import AnswerRecogniser

    word, conf, heard = answer_in(wav_to_16k(args.wav), AnswerRecogniser(), threshold, cfg.voice.max_segment_s,
                                  cfg.asking.third_answer)
    print(f"{word} {conf:.2f}")
    if args.verbose:
        for h in heard:
            print(f"  utterance {h.seconds:.2f} s: answer {h.answer}, confidence {h.confidence:.2f}, "
                  f"grammar '{h.words}', check '{h.check}', {h.decode_s * 1e3:.0f} ms", file=sys.stderr)
    return 0


def cmd_scenes(args: argparse.Namespace) -> int:
    for name in builtin_scene_names():
        s = load_scene(name)
        print(f"{name}: {len(s.objects)} objects, {len(s.goals)} goals")
        for g in s.goals:
            print(f"  {g.target:<34} {len(g.poses):>2} grasp poses")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sa-daemon", description="Shared-autonomy daemon for the xArm-6.")
    p.add_argument("--config", help="config.toml (default: built-in defaults)")
    sub = p.add_subparsers(dest="command", required=True)

    e = sub.add_parser("eval", help="run tasks x users x methods x seeds with simulated users")
    _add_scene(e, required=False)
    e.add_argument("--suite", choices=sorted(SUITES), help="a named experiment of the paper (docs/results.md)")
    e.add_argument("--task", action="append", help="object:grasp_type (repeatable; default: every target, or the suite's)")
    e.add_argument("--method", action="append", choices=METHODS, help="repeatable; default: all eight, or the suite's")
    e.add_argument("--user", action="append", metavar="NAME|FILE",
                   help=f"simulated user profile, repeatable (built-in: {', '.join(builtin_user_names())}; default calibrated)")
    e.add_argument("--seeds", type=int, help="seeds per cell (default 5; with --suite the suite's: 10, table1 20, "
                   "enough for a paired test to reach p < 0.05 after the Holm correction)")
    e.add_argument("--first-seed", type=int, default=0, help="seeds run from this one (default 0): extend an "
                   "earlier run with more seeds, then --merge it")
    e.add_argument("--merge", action="append", metavar="JSON",
                   help="an earlier --json run of the same config and arm whose trials join this run's before the "
                   "summary and the paired tests (repeatable; a trial measured twice is refused)")
    e.add_argument("--json", help="write trials and summary to this file")
    e.add_argument("--plots", help="write a Fig. 4 timeline per trial and Fig. 7 bar charts to this folder")
    e.add_argument("--jobs", type=int, default=cores(), help="worker processes (default: one per usable core)")
    e.add_argument("--arm", choices=SIMULATED_BACKENDS, default="kinematic",
                   help="kinematic: exact twist integration; mujoco: physics, success also needs a lift")
    e.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="local: this machine's process pool (--jobs); ray: a Ray cluster (extra: ray)")
    e.add_argument("--address", help="with --backend ray: an existing cluster (e.g. auto, ray://HOST:10001)")
    e.add_argument("--quiet", action="store_true", help="no progress bar")
    e.set_defaults(func=cmd_eval)

    b = sub.add_parser("bench", help="benchmarks that print figures")
    bsub = b.add_subparsers(dest="bench", required=True)
    bp = bsub.add_parser("planner", help="solver speed, anytime agreement, pomdp_py peer, belief update")
    _add_scene(bp)
    bp.add_argument("--json", help="write the figures to this file")
    bp.add_argument("--samples", type=int, default=200)
    bp.add_argument("--budget", type=float, default=0.1, help="anytime budget (s)")
    bp.add_argument("--no-peer", action="store_true", help="skip the pomdp_py comparison")
    bp.set_defaults(func=cmd_bench_planner)
    bv = bsub.add_parser("voice", help="answer recognition and false-accept rates on espeak-ng speech")
    bv.add_argument("--json", help="write the figures and every utterance's result to this file")
    bv.add_argument("--min-confidence", type=float, help="default: voice.min_confidence")
    bv.add_argument("--jobs", type=int, default=cores(), help="worker processes (default: one per usable core)")
    bv.add_argument("--third-answer", action="store_true",
                    help='with the third answer ("other grasp", asking.third_answer) and its phrases')
    bv.set_defaults(func=cmd_bench_voice)
    verbs.add_bench_parsers(bsub)

    h = sub.add_parser("hear", help="recognise an answer in a WAV file: prints yes, no or none (other with "
                       "asking.third_answer) and the confidence")
    h.add_argument("wav", help="16-bit PCM WAV, any rate")
    h.add_argument("--min-confidence", type=float, help="default: voice.min_confidence")
    h.add_argument("-v", "--verbose", action="store_true", help="every utterance found, on stderr")
    h.set_defaults(func=cmd_hear)

    s = sub.add_parser("scenes", help="list the built-in scenes and their goals")
    s.set_defaults(func=cmd_scenes)
    verbs.add_parsers(sub)
    _config_after_verb(sub)
    return p


def _config_after_verb(sub: argparse._SubParsersAction) -> None:
    """Accept ``--config`` after the verb too (``sa-daemon run --config c.toml``); SUPPRESS keeps a
    value given before the verb when it is not repeated."""
    for parser in sub.choices.values():
        nested = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if nested:
            _config_after_verb(nested[0])
        else:
            parser.add_argument("--config", default=argparse.SUPPRESS, help="config.toml (default: built-in defaults)")


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ConfigError, SceneError, KeyError, ValueError, OSError, TimeoutError, MissingExtra) as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else str(e)
        print(f"sa-daemon: error: {msg}", file=sys.stderr)
        return 2

