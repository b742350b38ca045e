"""Spoken questions: question text, real pyttsx3 + espeak-ng synthesis to WAV, and a speaker that never
blocks its caller (no engine, a failing engine, a hung engine)."""

from __future__ import annotations

import shutil
import threading
import time
import wave
from pathlib import Path

import pytest
from helpers import wav_stats

from sa_daemon.config import SpeechConfig
from sa_daemon.speech.speaker import Speaker, Spoken, question_text


@pytest.mark.parametrize(
    "target, text",
    [
        ("cup:top", "Is the cup with top grasp your goal?"),
        ("chips can:side", "Is the chips can with side grasp your goal?"),
        ("meat can:side_horizontal", "Is the meat can with side horizontal grasp your goal?"),
        ("bowl:top_vertical", "Is the bowl with top vertical grasp your goal?"),
        ("spoon", "Is the spoon your goal?"),
    ],
)
def test_question_text(target, text):
    assert question_text(target) == text


@pytest.mark.skipif(shutil.which("espeak-ng") is None, reason="espeak-ng is not installed (apt-get install espeak-ng)")
def test_real_utterance_becomes_a_non_silent_16_bit_mono_wav(tmp_path):
    done: list[Spoken] = []
    got = threading.Event()

    def on_done(s: Spoken) -> None:
        done.append(s)
        got.set()

    sp = Speaker(SpeechConfig(wav_dir=str(tmp_path / "wav"), play=False), on_done=on_done)
    try:
        assert sp.wait_ready(20.0), sp.error
        assert sp.available and sp.error is None
        text = question_text("chips can:side")
        assert sp.say(text) is True
        assert got.wait(60.0), "no utterance finished"
    finally:
        sp.close(timeout_s=10.0)
    s = done[0]
    assert s.text == text and s.error is None and s.played is False
    assert s.wav is not None and Path(s.wav).parent == tmp_path / "wav"
    assert "chips-can-with-side-grasp" in Path(s.wav).name and s.wav.endswith(".wav")
    ch, width, rate, duration, rms = wav_stats(s.wav)
    assert (ch, width) == (1, 2)
    assert rate >= 8000
    assert duration > 0.5
    assert rms > 500.0, f"silent WAV (RMS {rms:.1f} of 32767)"


def test_no_engine_means_unavailable_and_say_returns_false():
    def broken():
        raise RuntimeError("no espeak here")

    sp = Speaker(SpeechConfig(), engine_factory=broken)
    try:
        assert sp.wait_ready(5.0) is False
        assert sp.available is False
        assert "RuntimeError" in sp.error and "no espeak here" in sp.error
        assert sp.say("Is the cup with top grasp your goal?") is False
    finally:
        sp.close(timeout_s=2.0)


class FakeEngine:
    """pyttsx3's engine surface; ``runAndWait`` blocks until ``release`` (a hung driver) if ``hang``,
    raises if ``fail``, else writes a tiny WAV where ``save_to_file`` asked."""

    def __init__(self, hang: bool = False, fail: bool = False) -> None:
        self.hang, self.fail = hang, fail
        self.props: dict = {}
        self.entered = threading.Event()
        self.release = threading.Event()
        self.calls = 0
        self._path: str | None = None

    def setProperty(self, name, value):
        self.props[name] = value

    def save_to_file(self, text, path):
        self._path = path

    def runAndWait(self):
        self.calls += 1
        self.entered.set()
        if self.hang:
            self.release.wait(30.0)
        if self.fail:
            raise OSError("driver crashed")
        with wave.open(self._path, "wb") as w:
            w.setnchannels(1)
            w.setsampwidth(2)
            w.setframerate(22050)
            w.writeframes(b"\x00\x10" * 2205)


def test_engine_properties_come_from_the_config(tmp_path):
    eng = FakeEngine()
    sp = Speaker(SpeechConfig(rate_wpm=120, volume=0.5, wav_dir=str(tmp_path), play=False), engine_factory=lambda: eng)
    try:
        assert sp.wait_ready(5.0)
        assert eng.props == {"rate": 120, "volume": 0.5}
    finally:
        sp.close()


def test_a_failing_utterance_is_reported_and_speech_goes_on(tmp_path):
    eng = FakeEngine(fail=True)
    done: list[Spoken] = []
    sp = Speaker(SpeechConfig(wav_dir=str(tmp_path), play=False), on_done=done.append, engine_factory=lambda: eng)
    try:
        assert sp.wait_ready(5.0)
        assert sp.say("first")
        deadline = time.monotonic() + 10
        while not done and time.monotonic() < deadline:
            time.sleep(0.01)
        assert done and done[0].error is not None and "driver crashed" in done[0].error and done[0].wav is None
        eng.fail = False
        assert sp.say("second")
        while len(done) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert len(done) == 2 and done[1].error is None and Path(done[1].wav).is_file()
    finally:
        sp.close()


def test_a_hung_engine_never_blocks_say_and_drops_when_the_queue_is_full():
    eng = FakeEngine(hang=True)
    sp = Speaker(SpeechConfig(play=False), engine_factory=lambda: eng, max_pending=4)
    try:
        assert sp.wait_ready(5.0)
        assert sp.say("one") is True
        assert eng.entered.wait(10.0)  # the speech thread is now stuck in runAndWait
        assert sp.busy_since is not None
        results, slowest = [], 0.0
        for i in range(10):
            t0 = time.monotonic()
            results.append(sp.say(f"question {i}"))
            slowest = max(slowest, time.monotonic() - t0)
        assert results == [True] * 4 + [False] * 6  # four queued, then dropped
        assert sp.dropped == 6
        assert slowest < 0.5  # enqueueing only: never waits on the engine
        t0 = time.monotonic()
        sp.close(timeout_s=0.2)  # a hung engine is abandoned, close() does not wait for it
        assert time.monotonic() - t0 < 5.0
    finally:
        eng.release.set()
    # Once the engine comes back the thread ends: the stop request was not lost to the full queue,
    # and the utterances still queued are not spoken after close().
    sp._thread.join(10.0)
    assert not sp._thread.is_alive()
    assert eng.calls == 1
