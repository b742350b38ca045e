"""The adoption rules as ``docs/results/adopt.py`` checks them (session 19's, session 28's two forms and session 29's), on small
synthetic suites."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"


@pytest.fixture(scope="module")
def adopt():
    sys.path.insert(0, str(RESULTS))  # adopt.py imports report.py beside it, as when run as a script
    try:
        spec = importlib.util.spec_from_file_location("adopt", RESULTS / "adopt.py")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        yield mod
    finally:
        sys.path.remove(str(RESULTS))


def _suite(cells: dict[tuple[str, str, str, str], tuple[int, float, float]], n: int = 10) -> dict:
    """A suite file's trials (the fields ``sim.evaluate.summarise`` reads) and summary: per (scene, task,
    method, user), ``(successes of n, time s, correct-prediction rate)``."""
    trials, summary = [], []
    for (scene, task, method, user), (ok, time_s, pred) in cells.items():
        for seed in range(n):
            trials.append({"scene": scene, "task": task, "method": method, "user": user, "seed": seed,
                           "success": seed < ok, "completion_time_s": time_s if seed < ok else 100.0,
                           "correct_prediction": seed < round(pred * n), "questions": 0,
                           "final_target_p": 0.9 if seed < round(pred * n) else 0.5,
                           "mode_changes": 1, "joystick_input": 50.0, "opposing_pct": 0.0})
        summary.append({"scene": scene, "task": task, "method": method, "user": user,
                        "completion_time_s": time_s if ok else None})
    return {"trials": trials, "summary": summary, "comparisons": []}


def _verdict(adopt, old: dict, new: dict) -> list[str]:
    return adopt.judge(adopt.task_rows(_suite(new), _suite(old)), adopt.cell_changes(_suite(new), _suite(old)))


BASE = {("scene2", "drill", "policy", "u1"): (10, 20.0, 0.5),
        ("scene2", "drill", "ho", "u1"): (10, 30.0, 0.5),
        ("scene1", "cup", "policy", "u1"): (10, 10.0, 0.9)}


def test_a_better_option_is_adopted(adopt):
    better = {**BASE, ("scene2", "drill", "policy", "u1"): (10, 18.0, 0.8)}
    assert _verdict(adopt, BASE, better) == []


def test_two_lost_successes_pass_and_three_fail(adopt):
    up = {**BASE, ("scene2", "drill", "policy", "u1"): (10, 20.0, 0.8)}
    assert _verdict(adopt, BASE, {**up, ("scene2", "drill", "ho", "u1"): (8, 30.0, 0.5)}) == []
    fails = _verdict(adopt, BASE, {**up, ("scene2", "drill", "ho", "u1"): (7, 30.0, 0.5)})
    assert fails == ["(b) drill ho: 10 -> 7 successes"]


def test_prediction_crossing_the_floor_or_not_rising_on_scene2_fails(adopt):
    fails = _verdict(adopt, BASE, {**BASE, ("scene1", "cup", "policy", "u1"): (10, 10.0, 0.8)})
    assert "(a) cup: prediction 0.90 -> 0.80" in fails
    assert any(f.startswith("(a) Scene 2's prediction does not rise") for f in fails)


def test_more_slower_cells_than_faster_fails(adopt):
    up = {**BASE, ("scene2", "drill", "policy", "u1"): (10, 20.0, 0.8)}
    slower = {**up, ("scene1", "cup", "policy", "u1"): (10, 10.6, 0.9)}
    assert _verdict(adopt, BASE, slower) == ["(c) policy: 1 cells slower, 0 faster"]
    within = {**up, ("scene1", "cup", "policy", "u1"): (10, 10.4, 0.9)}
    assert _verdict(adopt, BASE, within) == []


def _flips(adopt, old: dict, new: dict, n: int):
    return adopt.prediction_flips(_suite(new, n), _suite(old, n))


def test_s28b_fails_a_task_only_when_its_lost_predictions_are_significant(adopt):
    """Session 28's second form: an exact one-sided McNemar test per task on the paired correct predictions
    (``_suite`` marks the first ``round(rate n)`` seeds correct, so a fall of k loses exactly k pairs)."""
    n = 20
    old = {("scene2", "drill", "policy", "u1"): (n, 20.0, 1.0)}
    lost4 = {("scene2", "drill", "policy", "u1"): (n, 20.0, 0.8)}
    lost5 = {("scene2", "drill", "policy", "u1"): (n, 20.0, 0.75)}
    (l4, g4, p4), = _flips(adopt, old, lost4, n).values()
    assert (l4, g4) == (4, 0) and p4 == pytest.approx(1 / 16)  # 0.0625: not below 0.05
    (l5, g5, p5), = _flips(adopt, old, lost5, n).values()
    assert (l5, g5) == (5, 0) and p5 == pytest.approx(1 / 32)
    rows = adopt.task_rows(_suite(lost5, n), _suite(old, n))
    cells = adopt.cell_changes(_suite(lost5, n), _suite(old, n))
    assert adopt.judge(rows, cells, flips=_flips(adopt, old, lost4, n)) == []
    assert adopt.judge(rows, cells, flips=_flips(adopt, old, lost5, n)) == [
        "(a'') scene2 drill: correct predictions lost 5, gained 0 (p = 0.031)"]


def test_s28_needs_the_log_p_shown_within_the_margin(adopt):
    """Session 28's first form: the lower end of the paired mean log p's 95 % interval above -0.1."""
    def suite(ps: list[float]) -> dict:
        return {"trials": [{"scene": "s", "task": "t", "method": "policy", "user": "u", "seed": i,
                            "final_target_p": p} for i, p in enumerate(ps)]}
    same = adopt.logp_changes(suite([0.9] * 40), suite([0.9] * 40))
    assert same[("s", "t")] == (0.0, 0.0, 0.0) and adopt.judge([], {}, logp=same) == []
    noisy = adopt.logp_changes(suite([0.99, 0.001] * 20), suite([0.001, 0.99] * 20))  # mean 0, wide
    m, lo, hi = noisy[("s", "t")]
    assert m == pytest.approx(0.0, abs=1e-12) and lo < -0.1 < 0.1 < hi
    assert adopt.judge([], {}, logp=noisy) == [f"(a') s t: log p {m:+.3f} [{lo:+.3f}, {hi:+.3f}]"]


def test_s29_judges_lost_successes_by_a_paired_test_per_task_and_pooled(adopt):
    """Session 29's form: (b') an exact one-sided McNemar test on the paired successes of each (task,
    method), and of all of them pooled, in place of (b)'s count (``_suite`` fails the last seeds, so a fall
    of k successes loses exactly k pairs)."""
    n = 20
    old = {("scene1", "cup", "policy", "u1"): (n, 10.0, 1.0), ("scene1", "bowl", "ho", "u1"): (n, 10.0, 1.0)}

    def verdict(new: dict) -> list[str]:
        a, b = _suite(new, n), _suite(old, n)
        return adopt.judge(adopt.task_rows(a, b), adopt.cell_changes(a, b), flips=adopt.prediction_flips(a, b),
                           successes=adopt.success_flips(a, b))

    assert verdict({**old, ("scene1", "cup", "policy", "u1"): (n - 3, 10.0, 1.0)}) == []  # (b) alone: off
    assert verdict({**old, ("scene1", "cup", "policy", "u1"): (n - 4, 10.0, 1.0)}) == []  # p = 1/16
    assert verdict({**old, ("scene1", "cup", "policy", "u1"): (n - 5, 10.0, 1.0)}) == [
        "(b') scene1 cup policy: successes lost 5, gained 0 (p = 0.031)",
        "(b') pooled: successes lost 5, gained 0 (p = 0.031)"]
    both3 = {("scene1", "cup", "policy", "u1"): (n - 3, 10.0, 1.0), ("scene1", "bowl", "ho", "u1"): (n - 3, 10.0, 1.0)}
    assert verdict(both3) == ["(b') pooled: successes lost 6, gained 0 (p = 0.016)"]  # each task 0.125
    assert adopt.mcnemar_lost(3, 0) == pytest.approx(0.125) and adopt.mcnemar_lost(0, 0) == 1.0
    assert adopt.mcnemar_lost(3, 3) == pytest.approx(42 / 64)


def test_s32_counts_cells_on_the_seeds_both_succeed(adopt):
    """Session 32's form: (c'') compares a cell's mean time over the seeds both configurations succeed on,
    so a mended time-out (a new success, slower than the rest) is not a slower cell, while a cell slower on
    the shared successes still is; (c) counts the mended cell as slower."""
    n = 10
    old = {("scene1", "cup", "policy", "u1"): (n - 1, 10.0, 1.0), ("scene1", "cup", "ho", "u1"): (n, 10.0, 1.0)}
    a, b = _suite(old, n), _suite(old, n)
    mended = next(t for t in a["trials"] if t["method"] == "policy" and not t["success"])
    mended.update(success=True, completion_time_s=28.0)  # the time-out now ends, slowly
    a["summary"][0]["completion_time_s"] = (10.0 * (n - 1) + 28.0) / n
    assert adopt.cell_changes(a, b) == {"policy": [0, 1], "ho": [0, 0]}
    assert adopt.paired_cell_changes(a, b) == {"policy": [0, 0], "ho": [0, 0]}
    for t in a["trials"]:
        if t["method"] == "ho":
            t["completion_time_s"] = 10.6  # 6 % slower on every shared success
    assert adopt.paired_cell_changes(a, b) == {"policy": [0, 0], "ho": [0, 1]}
    lost = next(t for t in a["trials"] if t["method"] == "policy" and t["success"] and t is not mended)
    lost.update(success=False, completion_time_s=100.0)  # a new failure drops out of the pairs
    assert adopt.paired_cell_changes(a, b)["policy"] == [0, 0]


def test_s37_weighs_issue_16s_targets_and_a_lost_prediction_is_not_a_veto(adopt, tmp_path, capsys):
    """Session 37's form: (t) in place of (a''). The option first loses `cup:side`'s prediction below 0.9 and
    gains the drill's: one target row for another, not more met, off. Then it keeps `cup:side` at 0.9: one
    more row met, adopted, though (a'') would have weighed the lost predictions on their own."""
    old = {("scene2", "drill:side_vertical", "policy", "u1"): (10, 20.0, 0.5),
           ("scene1", "cup:side", "policy", "u1"): (10, 10.0, 1.0)}
    new = {("scene2", "drill:side_vertical", "policy", "u1"): (10, 20.0, 1.0),
           ("scene1", "cup:side", "policy", "u1"): (10, 10.0, 0.8)}
    for tag, cells in (("old", old), ("new", new)):
        (tmp_path / f"suite-fig7-{tag}.json").write_text(json.dumps(_suite(cells)))
    files = {t: [tmp_path / f"suite-fig7-{t}.json"] for t in ("old", "new")}
    met_old, met_new = (adopt.targets_met(files[t]) for t in ("old", "new"))
    assert met_old[("correct prediction >= 0.9", "scene2 `drill:side_vertical`")] is False
    assert met_new[("correct prediction >= 0.9", "scene1 `cup:side`")] is False
    assert adopt.judge_targets(met_new, met_old) != []  # one row gained, one lost: not more
    better = {**new, ("scene1", "cup:side", "policy", "u1"): (10, 10.0, 0.9)}
    (tmp_path / "suite-fig7-new.json").write_text(json.dumps(_suite(better)))
    assert adopt.main(["new", "--dir", str(tmp_path), "--default", "old", "--default-dir", str(tmp_path),
                       "--rule", "s37"]) == 0
    out = capsys.readouterr().out
    assert "Rule s37: adopt" in out
    assert "correct prediction >= 0.9 (scene2 `drill:side_vertical`): False -> True" in out
    assert adopt.judge_targets(met_old, met_old) == ["(t) issue 16's targets met 2 -> 2"]  # prediction, success


def test_s39_needs_the_policy_significantly_faster_on_the_trials_both_succeed(adopt, tmp_path, capsys):
    """Session 39's form: s32 and (h). Ten paired trials each 1 s faster pass (exact two-sided p = 0.002);
    the same with one trial failing under the option pass on the nine left; five faster and five slower,
    or only three faster (p = 0.25), do not."""
    old = {("scene1", "cup:top", "policy", "u1"): (10, 10.0, 1.0)}
    a, b = _suite(old), _suite(old)
    for t in a["trials"]:
        t["completion_time_s"] = 9.0
    assert adopt.judge_times(*adopt.paired_times(a, b)) == []
    a["trials"][0].update(success=False, completion_time_s=100.0)
    option, default = adopt.paired_times(a, b)
    assert len(option) == 9 and adopt.judge_times(option, default) == []
    for t in a["trials"][:5]:
        t.update(success=True, completion_time_s=11.0)
    assert adopt.judge_times(*adopt.paired_times(a, b))[0].startswith("(h) paired time over 10 trials")
    for i, t in enumerate(a["trials"]):
        t["completion_time_s"] = 9.0 if i < 3 else 10.0
    assert adopt.judge_times(*adopt.paired_times(a, b)) != []
    for tag, suite in (("old", b), ("new", {**a, "trials": [{**t, "completion_time_s": 9.0} for t in a["trials"]]})):
        (tmp_path / f"suite-table1-{tag}.json").write_text(json.dumps(suite))
    assert adopt.main(["new", "--dir", str(tmp_path), "--default", "old", "--default-dir", str(tmp_path),
                       "--rule", "s39"]) == 0
    assert "Rule s39: adopt" in capsys.readouterr().out


def test_s39b_reads_the_changed_trials_where_s39_s_median_sees_only_the_unchanged(adopt):
    """Thirty unchanged trials and eight each 3 s faster: the median difference is 0, so (h) refuses what
    (h') (the mean, -0.63 s; exact p = 0.008 on the eight) takes. Eight slower the same way: both refuse."""
    option, default = [10.0] * 30 + [7.0] * 8, [10.0] * 38
    assert adopt.judge_times(option, default)[0].startswith("(h) paired time over 38 trials: median difference 0.000")
    assert adopt.judge_times(option, default, centre="mean") == []
    slower = [10.0] * 30 + [13.0] * 8
    assert adopt.judge_times(slower, default, centre="mean")[0].startswith("(h') paired time over 38 trials: mean")
