"""Spoken questions: question text, real espeak-ng synthesis to WAV (from the system library or
the pip wheel's), what happens to each question (played / written / unavailable), and a speaker that never
blocks its caller (no engine, a failing engine, a hung engine)."""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
import threading
import time
import wave
from pathlib import Path

import pytest
from helpers import synth_wavs, wav_stats

from sa_daemon.config import SpeechConfig
from sa_daemon.speech.engine import engine
from sa_daemon.speech.espeak import read_wav
from sa_daemon.speech.speaker import Speaker, Spoken, echo_text, question_text


def _system_espeak() -> bool:
    """Whether the dynamic loader finds a system libespeak-ng (checked apart from the code under test)."""
    try:
        ctypes.CDLL("libespeak-ng.so.1")
    except OSError:
        return False
    return True


needs_system_espeak = pytest.mark.skipif(
    not _system_espeak(), reason="no system espeak-ng library here (apt-get install libespeak-ng1)")


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


@pytest.mark.parametrize("answer, target, text", [
    ("yes", "cup:top", "Yes: the cup, top grasp"),
    ("no", "meat can:side_horizontal", "No: the meat can, side horizontal grasp"),
    ("yes", "spoon", "Yes: the spoon"),
    ("other", "cup:top", "Another grasp of the cup"),
])
def test_echo_text(answer, target, text):
    assert echo_text(answer, target) == text


@pytest.mark.parametrize("library", ["wheel", pytest.param("system", marks=needs_system_espeak)])
def test_each_library_speaks_a_non_silent_wav(tmp_path, library):
    """The wheel's library needs no system package; the system's is used when asked (and by auto)."""
    lib = synth_wavs(tmp_path, {"q": ("Is the cup with top grasp your goal?", "en-us", 150)}, library)
    assert lib["source"] == library
    assert lib["version"].startswith("1.")
    if library == "wheel":
        assert "espeakng_loader" in lib["path"] and lib["data_path"].endswith("espeak-ng-data")
    ch, width, rate, duration, rms = wav_stats(tmp_path / "q.wav")
    assert (ch, width, rate) == (1, 2, 22050)
    assert 1.0 < duration < 5.0 and rms > 500.0


def test_auto_takes_the_system_library_when_there_is_one_else_the_wheel(tmp_path):
    lib = synth_wavs(tmp_path, {"q": ("yes", "en", 150)}, "auto")
    assert lib["source"] == ("system" if _system_espeak() else "wheel")


def test_without_any_library_speech_is_unavailable_with_the_reason(tmp_path):
    """The wheel missing and no system library: one clear error, no crash (a child process whose import
    of espeakng_loader fails and whose loader path finds no libespeak-ng)."""
    code = (
        "import sys; sys.modules['espeakng_loader'] = None\n"
        "from sa_daemon.speech import espeak\n"
        "try:\n espeak.load('wheel')\nexcept espeak.SpeechUnavailable as e:\n print('unavailable:', e)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("unavailable: no espeak-ng library (wheel: the espeakng-loader wheel is not installed")
    assert "pip install espeakng-loader" in r.stdout


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
    assert s.text == text and s.error is None and s.played is False and s.outcome == "written"
    assert s.wav is not None and Path(s.wav).parent == tmp_path / "wav"
    assert "chips-can-with-side-grasp" in Path(s.wav).name and s.wav.endswith(".wav")
    ch, width, rate, duration, rms = wav_stats(s.wav)
    assert (ch, width) == (1, 2)
    assert rate >= 8000
    assert duration > 0.5
    assert rms > 500.0, f"silent WAV (RMS {rms:.1f} of 32767)"


def test_an_unknown_voice_at_start_is_unavailable_speech_naming_the_key():
    sp = Speaker(SpeechConfig(voice="xx-no-such-voice", play=False), engine_factory=FakeEngine)
    try:
        assert sp.wait_ready(5.0) is False and sp.mode == "unavailable"
        assert sp.error.startswith("speech unavailable: ValueError: speech.voice: ") and "xx-no-such-voice" in sp.error
    finally:
        sp.close(timeout_s=2.0)


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
    """The engine's surface (``speech.engine.Engine``); ``save_wav`` blocks until ``release`` (a hung
    driver) if ``hang``, raises if ``fail``, else writes a tiny WAV. ``voices`` the voices it knows."""

    def __init__(self, hang: bool = False, fail: bool = False, voices: tuple[str, ...] = ("", "en-us")) -> None:
        self.hang, self.fail, self.voices = hang, fail, voices
        self.props: dict = {}
        self.entered = threading.Event()
        self.release = threading.Event()
        self.calls = 0

    def configure(self, rate_wpm=None, volume=None, voice=None):
        if voice is not None and voice not in self.voices:
            raise ValueError(f"espeak-ng has no voice {voice!r}")
        self.props.update({k: v for k, v in (("rate", rate_wpm), ("volume", volume), ("voice", voice)) if v is not None})

    def save_wav(self, text, path):
        self.calls += 1
        self.entered.set()
        if self.hang:
            self.release.wait(30.0)
        if self.fail:
            raise OSError("driver crashed")
        with wave.open(str(path), "wb") as w:
            w.setnchannels(1)
            w.setsampwidth(2)
            w.setframerate(22050)
            w.writeframes(b"\x00\x10" * 2205)


def test_engine_properties_come_from_the_config(tmp_path):
    eng = FakeEngine()
    sp = Speaker(SpeechConfig(rate_wpm=120, volume=0.5, wav_dir=str(tmp_path), play=False), engine_factory=lambda: eng)
    try:
        assert sp.wait_ready(5.0)
        assert eng.props == {"rate": 120, "volume": 0.5, "voice": ""}
    finally:
        sp.close()


def test_each_utterance_is_spoken_at_its_own_rate_the_same_in_every_process(tmp_path):
    """pyttsx3's espeak driver (sessions 1-23) ran espeak-ng asynchronously and applied a new rate late,
    at random: 120 words a minute after 200 came out at either. The engine is synchronous: each
    utterance at its own rate, the same length in two processes (the same samples too with Debian's
    1.51; the wheel's 1.52 varies the noise of breathy variants such as +f2 from process to process)."""
    rates = (120, 200, 120, 200, 160, 120, 200, 120)
    items = {f"u{i}": ("another grasp please", "en-us+f2", r) for i, r in enumerate(rates)}
    runs = []
    for run in ("a", "b"):
        synth_wavs(tmp_path / run, items)
        runs.append({n: read_wav(tmp_path / run / f"{n}.wav")[0] for n in items})
    assert all(len(runs[0][n]) == len(runs[1][n]) for n in items)
    by_rate = {r: [len(runs[0][f"u{i}"]) for i, q in enumerate(rates) if q == r] for r in set(rates)}
    assert max(by_rate[200]) < min(by_rate[160]) <= max(by_rate[160]) < min(by_rate[120]), by_rate
    assert max(by_rate[120]) - min(by_rate[120]) < 0.02 * min(by_rate[120]), by_rate


def test_an_unknown_voice_is_refused_and_changes_nothing():
    eng = engine()
    eng.configure(rate_wpm=150, volume=1.0, voice="en-us")
    before = eng.synthesise("yes")
    with pytest.raises(ValueError, match="no voice 'xx-no-such-voice'"):
        eng.configure(rate_wpm=300, voice="xx-no-such-voice")
    assert eng.voice == "en-us"
    after = eng.synthesise("yes")  # espeak-ng carries a few samples of state from one utterance to the next
    assert abs(len(after) - len(before)) < 0.01 * len(before)  # at 300 words a minute: far shorter


def test_a_profile_with_an_unknown_voice_is_named_and_the_previous_voice_speaks_on(tmp_path):
    eng = FakeEngine()
    done: list[Spoken] = []
    sp = Speaker(SpeechConfig(voice="en-us", wav_dir=str(tmp_path), play=False), on_done=done.append,
                 engine_factory=lambda: eng)
    try:
        assert sp.wait_ready(5.0)
        sp.configure(SpeechConfig(voice="xx-no-such-voice", rate_wpm=300, wav_dir=str(tmp_path), play=False))
        assert sp.say("first") and sp.say("second")
        deadline = time.monotonic() + 10
        while len(done) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert [s.outcome for s in done] == ["written", "written"]
        assert "speech.voice" in done[0].error and "xx-no-such-voice" in done[0].error
        assert "kept the previous voice" in done[0].error and done[1].error is None
        assert eng.props == {"voice": "en-us", "rate": 150, "volume": 1.0}  # nothing changed
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
        assert eng.entered.wait(10.0)  # the speech thread is now stuck in save_wav
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


FAKE_APLAY = """#!/bin/sh
# aplay's documented call here: aplay -q FILE.wav; this one checks the file is a WAV and records it.
[ "$1" = "-q" ] || { echo "aplay: unexpected arguments $*" >&2; exit 2; }
head -c 4 "$2" | grep -q RIFF || { echo "aplay: $2: not a WAV" >&2; exit 1; }
echo "$2" >> "$APLAY_LOG"
"""


def _speak_once(cfg: SpeechConfig) -> tuple[Speaker, Spoken]:
    done: list[Spoken] = []
    got = threading.Event()
    sp = Speaker(cfg, on_done=lambda s: (done.append(s), got.set()))
    assert sp.wait_ready(20.0), sp.error
    assert sp.say("Is the bowl with top grasp your goal?")
    assert got.wait(60.0)
    return sp, done[0]


def test_with_a_player_questions_are_played(tmp_path, monkeypatch):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "aplay").write_text(FAKE_APLAY)
    (bin_dir / "aplay").chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv("APLAY_LOG", str(tmp_path / "played.txt"))
    sp, s = _speak_once(SpeechConfig(play=True))
    try:
        assert sp.mode == "played" and sp.player_missing is None
        assert sp.status()["player"] == str(bin_dir / "aplay")
        assert s.outcome == "played" and s.played and s.error is None and s.wav is None
        assert len((tmp_path / "played.txt").read_text().split()) == 1  # the temporary WAV was played
    finally:
        sp.close()


def test_without_a_player_questions_are_written_and_the_missing_player_is_named(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))  # no aplay anywhere
    sp, s = _speak_once(SpeechConfig(play=True, wav_dir=str(tmp_path / "wav")))
    try:
        assert sp.mode == "written"
        assert sp.player_missing == ("aplay not found: questions are written as WAV files, not played "
                                     "(install the alsa-utils package, e.g. apt-get install alsa-utils)")
        assert s.outcome == "written" and not s.played and s.error is None
        assert wav_stats(s.wav)[4] > 500.0
        st = sp.status()
        assert st["mode"] == "written" and st["player"] is None and st["library"]["source"] in ("system", "wheel")
    finally:
        sp.close()


def test_play_off_is_written_and_no_player_is_missing(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    sp = Speaker(SpeechConfig(play=False))
    try:
        assert sp.wait_ready(20.0)
        assert sp.mode == "written" and sp.player_missing is None
    finally:
        sp.close()


def test_no_engine_is_the_unavailable_state():
    def broken():
        raise RuntimeError("no espeak here")

    sp = Speaker(SpeechConfig(), engine_factory=broken)
    try:
        assert sp.wait_ready(5.0) is False
        assert sp.mode == "unavailable" and sp.status()["error"] == "speech unavailable: RuntimeError: no espeak here"
    finally:
        sp.close()
