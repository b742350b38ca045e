"""Offline recognition of one spoken answer with pocketsphinx (the ``voice`` extra).

The pocketsphinx wheel ships an en-US acoustic model, the CMU dictionary and a general English
trigram model, so nothing is downloaded. One utterance (16 kHz mono int16, cut out by the listener's
voice-activity detection) goes through two searches of one decoder:

1. **answer**: a closed JSGF grammar of the answers (:data:`YES_WORDS`, :data:`NO_WORDS`, "yes
   please", "no thanks"; with ``third`` also the third answer, :data:`OTHER_WORDS` + "grasp": "other
   grasp", ``asking.third_answer``). It always finds *some* answer: "maybe" and "hello" come out as "yeah".
2. **check**: the general English language model over the whole dictionary, the garbage model that
   every other word and phrase falls into. The utterance is an answer only if this free transcript
   says the same: for yes and no, it is itself made of answer words of the same polarity (at most two
   words); for the third answer, it holds one of :data:`OTHER_WORDS` followed at once by a word that
   begins like "grasp" (the language model spells it "grass", "grasses", "grants"...), in at most three
   words, none of them a yes or no word.

``confidence`` is the check's posterior probability of its transcript (pocketsphinx's lattice
posterior, 0-1) when the two agree, and 0 when they do not; the listener ignores answers below
``voice.min_confidence``. Why this design and its measured rates (``sa-daemon bench voice``):
``docs/daemon.md``. A closed grammar alone, keyword spotting, a phone-loop garbage model and a
per-frame acoustic-score floor were measured first and rejected there.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from ..extras import require

SAMPLE_RATE = 16000
YES_WORDS = ("yes", "yeah", "yep", "yup")
NO_WORDS = ("no", "nope", "nah")
OTHER_WORDS = ("another", "other", "different")  # + "grasp": "that object, another grasp"
_YES_CHECK = set(YES_WORDS) | {"yea", "ya", "please"}  # the LM's spellings of the same sounds, and "yes please"
_NO_CHECK = set(NO_WORDS) | {"thanks"}
_FILLERS = {"<s>", "</s>", "<sil>", "(NULL)", "[NOISE]", "[SPEECH]"}

_YES_NO = f"""<yes> = {' | '.join(YES_WORDS)} | yes please;
<no> = {' | '.join(NO_WORDS)} | no thanks;
"""
GRAMMAR = f"""#JSGF V1.0;
grammar answer;
public <answer> = <yes> | <no>;
{_YES_NO}"""
GRAMMAR_THIRD = f"""#JSGF V1.0;
grammar answer3;
public <answer> = <yes> | <no> | <other>;
{_YES_NO}<other> = ({' | '.join(OTHER_WORDS)}) grasp;
"""


@dataclass(frozen=True)
class Heard:
    """What one utterance was: ``answer`` (``yes``, ``no``, ``other`` or ``none``), ``confidence`` (0-1),
    ``words`` (the answer grammar's reading), ``check`` (the free transcript), ``seconds`` of audio and
    ``decode_s`` (time the two searches took)."""

    answer: str
    confidence: float
    words: str
    check: str
    seconds: float
    decode_s: float

    def as_dict(self) -> dict:
        return {"answer": self.answer, "confidence": round(self.confidence, 3), "words": self.words,
                "check": self.check, "seconds": round(self.seconds, 3), "decode_s": round(self.decode_s, 3)}


def polarity(words: str, yes: set[str], no: set[str]) -> str:
    """``yes`` / ``no`` if ``words`` (at most two) are all of one set, else ``none``."""
    w = words.split()
    if not w or len(w) > 2:
        return "none"
    if all(x in yes for x in w) and w[0] != "please":
        return "yes"
    if all(x in no for x in w) and w[0] != "thanks":
        return "no"
    return "none"


def is_other(words: str) -> bool:
    """Whether ``words`` (a free transcript) say the third answer: at most three words, one of
    :data:`OTHER_WORDS` followed at once by a word beginning with "gra", and no yes or no word."""
    w = words.split()
    if not w or len(w) > 3 or any(x in _YES_CHECK or x in _NO_CHECK for x in w):
        return False
    return any(a in OTHER_WORDS and b.startswith("gra") for a, b in pairwise(w))


class AnswerRecogniser:
    """One pocketsphinx decoder with the two searches of the module doc. Not thread-safe; ~0.1 s to
    build, ~10 ms (answer) + 0.1-0.4 s (check) per utterance on one core of this machine."""

    def __init__(self) -> None:
        ps = require("pocketsphinx", "voice")
        model = ps.get_model_path()
        self._decoder = ps.Decoder(
            hmm=os.path.join(model, "en-us", "en-us"),
            dict=os.path.join(model, "en-us", "cmudict-en-us.dict"),
            lm=None, samprate=SAMPLE_RATE, loglevel="FATAL",
        )
        self._decoder.add_jsgf_string("answer", GRAMMAR)
        self._decoder.add_jsgf_string("answer3", GRAMMAR_THIRD)
        self._decoder.add_lm_file("check", os.path.join(model, "en-us", "en-us.lm.bin"))

    def _search(self, name: str, pcm: bytes) -> tuple[str, float]:
        d = self._decoder
        d.activate_search(name)
        d.start_utt()
        d.process_raw(pcm, False, True)
        d.end_utt()
        h = d.hyp()
        if h is None:
            return "", 0.0
        words = " ".join(w for w in h.hypstr.split() if w not in _FILLERS)
        return words, float(h.prob)

    def recognise(self, pcm: np.ndarray, third: bool = False) -> Heard:
        """Classify one utterance (int16 samples at :data:`SAMPLE_RATE`, a little silence around it helps);
        ``third``: the third answer ("other grasp") is one of the answers."""
        t0 = time.perf_counter()
        x = np.ascontiguousarray(pcm, dtype="<i2")
        raw = x.tobytes()
        words, _ = self._search("answer3" if third else "answer", raw)
        if third and is_other(words):
            answer = "other"
        else:
            answer = polarity(words, set(YES_WORDS) | {"please"}, set(NO_WORDS) | {"thanks"})
        check, posterior = ("", 0.0)
        confidence = 0.0
        if answer != "none":
            check, posterior = self._search("check", raw)
            agrees = is_other(check) if answer == "other" else polarity(check, _YES_CHECK, _NO_CHECK) == answer
            if agrees:
                confidence = min(max(posterior, 0.0), 1.0)
            else:
                answer = "none"
        return Heard(answer, confidence, words, check, len(x) / SAMPLE_RATE, time.perf_counter() - t0)


def to_16k(x: np.ndarray, rate: int) -> np.ndarray:
    """Resample int16 audio at ``rate`` Hz to :data:`SAMPLE_RATE` (polyphase, scipy)."""
    if rate == SAMPLE_RATE:
        return np.asarray(x, dtype=np.int16)
    from math import gcd

    from scipy.signal import resample_poly

    g = gcd(SAMPLE_RATE, rate)
    y = resample_poly(np.asarray(x, dtype=float), SAMPLE_RATE // g, rate // g)
    return np.clip(np.round(y), -32768, 32767).astype(np.int16)
