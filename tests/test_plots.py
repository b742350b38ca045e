"""Plots of a trial timeline (Fig. 4) and of summary bars (Fig. 7): real data, valid non-blank PNGs."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image as mpimg
import matplotlib.pyplot as plt
import numpy as np
import pytest

from sa_daemon.config import Config
from sa_daemon.sim.episode import TrialResult, run_trial
from sa_daemon.sim.evaluate import summarise
from sa_daemon.sim.plots import plot_summary_bars, plot_timeline
from sa_daemon.world.scene import load_scene

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def trial() -> TrialResult:
    return run_trial(load_scene("scene1"), "cup:top", "policy", 0, Config(), record=True)


def _check_png(path: Path, min_w: int, min_h: int) -> np.ndarray:
    assert path.is_file()
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > 10_000
    img = mpimg.imread(path)
    h, w = img.shape[:2]
    assert min_w <= w <= 4000 and min_h <= h <= 4000
    assert float(np.std(img[..., :3])) > 0.0
    return img


def test_timeline_png(trial: TrialResult, tmp_path: Path) -> None:
    assert trial.timeline is not None and len(trial.timeline.t) > 10
    out = plot_timeline(trial, tmp_path / "sub" / "timeline.png")
    assert out == tmp_path / "sub" / "timeline.png"
    img = _check_png(out, 800, 1000)
    assert img.shape[0] > img.shape[1]  # a vertical stack of panels
    assert plt.get_fignums() == []


def test_timeline_needs_record(trial: TrialResult, tmp_path: Path) -> None:
    bare = run_trial(load_scene("scene1"), "cup:top", "ho", 0, Config())
    assert bare.timeline is None
    with pytest.raises(ValueError, match="timeline"):
        plot_timeline(bare, tmp_path / "none.png")
    assert not (tmp_path / "none.png").exists()
    assert plt.get_fignums() == []


def test_timeline_repeated_calls_do_not_leak(trial: TrialResult, tmp_path: Path) -> None:
    for i in range(3):
        plot_timeline(trial, tmp_path / f"t{i}.png")
    assert plt.get_fignums() == []


def test_summary_bars_from_real_trials(tmp_path: Path) -> None:
    scene, cfg = load_scene("scene1"), Config()
    trials = [run_trial(scene, "cup:top", m, 0, cfg).metrics() for m in ("ho", "policy")]
    rows = summarise(trials)
    assert [r["method"] for r in rows] == ["ho", "policy"]
    out = plot_summary_bars(rows, tmp_path / "bars.png", title="scene1, 1 seed")
    _check_png(out, 800, 400)
    assert plt.get_fignums() == []


def test_summary_bars_with_missing_values(tmp_path: Path) -> None:
    def row(task: str, method: str, ok: bool) -> dict:
        r = {"scene": "scene2", "task": task, "method": method, "n": 5, "success_rate": 0.8 if ok else 0.0,
             "correct_prediction_rate": 0.6, "questions": 1.2 if method == "policy" else 0.0}
        for i, k in enumerate(("completion_time_s", "mode_changes", "joystick_input", "opposing_pct")):
            r[k] = (10.0 + i) if ok else None
            r[k + "_std"] = 1.5 if ok else None
        return r

    rows = [row("cup:top", "ho", True), row("cup:top", "policy", True), row("bowl:top", "ho", False),
            row("bowl:top", "policy", True), row("spoon:side", "ho+noassist", True)]
    rows[1]["opposing_pct_std"] = None  # a value without its spread
    out = plot_summary_bars(rows, tmp_path / "bars_none.png")
    _check_png(out, 800, 400)
    assert plt.get_fignums() == []


def test_summary_bars_empty(tmp_path: Path) -> None:
    with pytest.raises(ValueError):
        plot_summary_bars([], tmp_path / "empty.png")
