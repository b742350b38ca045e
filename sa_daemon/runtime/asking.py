"""Questions aloud and answers from anywhere: the daemon's side of the controller's pending question.

The :class:`~..control.controller.Controller` decides *that* a question is pending and applies the answer;
this module says it (``speech/speaker.py``), opens a listening window once it has been said
(``speech/listener.py``), accepts a spoken answer above ``voice.min_confidence``, and publishes every
step as an event (``docs/protocol.md``). Answers from a button, the protocol or the simulated user come in
through :meth:`Asker.answer` too. Speech and voice callbacks arrive on their own threads and are moved
onto the event loop here.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import Any

from ..config import Config
from ..control.controller import Controller
from ..control.outputs import NoQuestion, Question, answer_word
from ..io.protocol import RequestError
from ..speech.speaker import Speaker, Spoken, echo_text, question_text

log = logging.getLogger("sa_daemon")

Event = Callable[..., None]


class Asker:
    """Speaks the controller's questions, listens for spoken answers, applies every answer.

    ``event(kind, **fields)`` publishes; ``speaker`` and ``voice`` are optional (``None``: not configured).
    Times are ``time.monotonic()`` seconds, the daemon's controller clock.
    """

    def __init__(self, cfg: Config, ctl: Controller, event: Event, speaker: Speaker | None = None,
                 voice: Any = None) -> None:
        self._cfg, self._ctl, self._event = cfg, ctl, event
        self.speaker = speaker
        self.voice = voice  # speech.listener.VoiceListener when voice.enabled
        self._loop: asyncio.AbstractEventLoop | None = None

    def reconfigure(self, cfg: Config) -> None:
        """A person's profile: the answer sources they use, their voice, rate and volume. (Their answer
        times count afresh in the controller's :class:`~..control.answer_time.AnswerTime`.)"""
        self._cfg = cfg
        if self.speaker is not None:
            self.speaker.configure(cfg.speech)

    def bind(self, loop: asyncio.AbstractEventLoop) -> None:
        """The event loop that speech and voice callbacks are moved onto."""
        self._loop = loop

    @staticmethod
    def text(q: Question) -> str:
        return question_text(q.target)

    # -- asking ------------------------------------------------------------------------------------------

    def asked(self, q: Question) -> None:
        """The controller has just posed ``q``: say it, publish it, and listen once it has been said (at
        once if nothing will be said)."""
        text = self.text(q)
        queued = self.speaker is not None and self.speaker.say(text)
        spoken = self.speaker.mode if queued else "unavailable"  # type: ignore[union-attr]
        self._event("question", goal=q.target, text=text, spoken=spoken)
        if not queued:
            self._listen(q)

    def cleared(self) -> None:
        """The pending question is gone (answered, timed out, dropped): stop listening for it."""
        if self.voice is not None:
            self.voice.mute()

    def answer(self, answer: bool | str, source: str, **detail: Any) -> None:
        """Apply an answer to the pending question (``True``/``"yes"``, ``False``/``"no"``, ``"other"``);
        :class:`RequestError` with the reason if there is none or it cannot be taken. ``detail`` (a voice
        answer's ``confidence``) goes into the ``answer`` event."""
        now = time.monotonic()
        if source in ("button", "command", "voice") and source not in self._cfg.asking.answer_sources:
            raise RequestError(f"answers by {source} are off (asking.answer_sources)")
        value = answer_word(answer)
        try:
            q = self._ctl.on_answer(value, now)
        except NoQuestion as e:
            raise RequestError(str(e)) from None
        except ValueError as e:  # the third answer off, or the object has one grasp type only
            raise RequestError(str(e)) from None
        self.cleared()
        self._event("answer", goal=q.target, value=value, source=source, after_s=round(now - q.asked_at, 3),
                    charged_s=round(self._ctl.answer_time.charged_s, 6), **detail)

    def expire(self, now: float) -> None:
        """Drop the pending question after ``runtime.question_timeout_s``."""
        q = self._ctl.expire_question(now)
        if q is not None:
            self.cleared()
            self._event("question_timeout", goal=q.target)

    # -- speech (speech/speaker.py) ----------------------------------------------------------------------

    def on_spoken(self, s: Spoken) -> None:
        """(The speech thread.) An utterance finished."""
        loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._spoken, s)

    def _spoken(self, s: Spoken) -> None:
        self._event("spoken", text=s.text, outcome=s.outcome, wav=s.wav, played=s.played,
                    seconds=round(s.seconds, 3), error=s.error)
        q = self._ctl.question
        if q is not None and s.text == self.text(q) and not (self.speaker and self.speaker.speaking):
            self._listen(q)  # the question has been said: its answer may come now

    # -- voice (speech/listener.py) ----------------------------------------------------------------------

    def voice_ready(self) -> None:
        """The voice process has just become ready: a question said while it was starting (the planner
        may ask before the recogniser has loaded) gets its listening window now."""
        q = self._ctl.question
        if q is not None and not (self.speaker and self.speaker.speaking):
            self._listen(q)

    def _third(self, q: Question) -> bool:
        """Whether "other grasp" answers ``q``: ``asking.third_answer`` is on and its object has another
        grasp type."""
        return self._cfg.asking.third_answer and bool(self._ctl.belief.siblings(q.target))

    def _listen(self, q: Question) -> None:
        if self.voice is None or not self.voice.ready:
            return
        vc = self._cfg.voice
        t_open = time.monotonic() + vc.after_speech_s
        self.voice.listen(q.qid, t_open, t_open + vc.listen_s, self._third(q))
        self._event("listening", goal=q.target, for_s=vc.listen_s)

    def on_heard(self, qid: int, heard: dict[str, Any], t_start: float, t_end: float) -> None:
        """The voice process recognised an utterance inside a listening window."""
        q = self._ctl.question
        value = heard.get("answer", "none")
        vc = self._cfg.voice
        if q is None or q.qid != qid:
            reason = "no question pending"
        elif value not in ("yes", "no") and not (value == "other" and self._third(q)):
            reason = heard.get("reason", "not an answer")
        elif heard["confidence"] < vc.min_confidence:
            reason = f"confidence below voice.min_confidence {vc.min_confidence:g}"
        elif "voice" not in self._cfg.asking.answer_sources:
            reason = "answers by voice are off (asking.answer_sources)"
        else:
            reason = None
        self._event("heard", **heard, accepted=reason is None, reason=reason,
                    latency_s=round(time.monotonic() - t_end, 3))
        if reason is not None or q is None:
            return
        self.answer(value, source="voice", confidence=heard["confidence"])
        if vc.echo and self.speaker is not None:
            self.speaker.say(echo_text(value, q.target))

    def on_voice_error(self, text: str) -> None:
        log.error("voice: %s", text)
        self._event("voice_unavailable", error=text)
