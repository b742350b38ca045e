"""``sa-daemon web`` (issue 18): the page against a live daemon with the simulated user.

Real processes and sockets throughout: the daemon (kinematic arm, simulated user) and the page server
are ``sa-daemon`` subprocesses; the tests talk to the page over HTTP and WebSocket with aiohttp, and
drive Debian's headless Chromium through its chromedriver (``selenium``). Without Chromium the browser
tests skip, saying so; CI installs it (``.ci/run``).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import shutil
import socket
import subprocess
import time
from pathlib import Path

import aiohttp
import pytest
from helpers import CLI, COMMIT_MODEL_TOML, DaemonProc, free_port, until
from hypothesis import given, settings
from hypothesis import strategies as st

from sa_daemon.config import ConfigError, WebConfig
from sa_daemon.web.link import PAGE_COMMANDS, PageMessageError, parse_page_message
from sa_daemon.web.server import check_exposure, read_token, split_listen

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
HAVE_BROWSER = os.path.exists(CHROMIUM) and os.path.exists(CHROMEDRIVER)
NO_BROWSER = "Debian's chromium and chromium-driver are not installed (.ci/run installs them)"
PERIOD_S = 1.0 / 100  # the daemon's control period (runtime.control_hz)
#: The daemon asks early (commit model) and its simulated user waits 60 s to answer, so the page answers.
DAEMON_TOML = COMMIT_MODEL_TOML + "[sim_user]\nanswer_delay_s = 60.0\n[speech]\nenabled = false\n"


# -- pure pieces ------------------------------------------------------------------------------------------


def test_page_messages_are_the_protocols_requests_limited_to_what_the_page_offers():
    assert parse_page_message('{"cmd": "answer", "value": "yes"}', 4096).args == {"value": "yes"}
    assert parse_page_message(b'{"cmd": "stop"}', 4096).cmd == "stop"
    for bad, why in (('{"cmd": "answer", "value": "maybe"}', '"value" must be "yes", "no" or "other"'),
                     ('{"cmd": "launch"}', "unknown command"), ("[1, 2]", "must be a JSON object"),
                     ('{"cmd": "stop", "x": 1}', "unexpected field"), ("{" * 10 + "}" * 10, "nested deeper"),
                     ('{"cmd": "stop", "pad": "' + "a" * 5000 + '"}', "too large"), ("NaN", "not JSON")):
        with pytest.raises(PageMessageError, match=why):
            parse_page_message(bad, 4096)
    # the page's commands are protocol commands, and the page's script sends no other
    import re

    from sa_daemon.io.protocol import COMMANDS
    from sa_daemon.web.server import STATIC

    sent = set(re.findall(r'cmd: "([a-z_]+)"', (STATIC / "app.js").read_text()))
    assert sent <= set(PAGE_COMMANDS) <= set(COMMANDS) and {"stop", "resume", "answer"} <= sent


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.text(max_size=300), st.binary(max_size=300),
                 st.recursive(st.none() | st.booleans() | st.floats() | st.text(max_size=20),
                              lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=8), c, max_size=4),
                              max_leaves=20).map(lambda v: json.dumps(v, allow_nan=True))))
def test_fuzzed_page_input_is_a_request_or_refused_with_a_reason(raw):
    try:
        req = parse_page_message(raw, 4096)
    except PageMessageError as e:
        assert str(e)
    else:
        assert req.cmd in PAGE_COMMANDS


def test_exposure_needs_tls_and_a_token_naming_the_key(tmp_path):
    assert split_listen("127.0.0.1:8080") == ("127.0.0.1", 8080) and split_listen("[::1]:9") == ("::1", 9)
    with pytest.raises(ConfigError, match="web.listen"):
        split_listen("8080")
    check_exposure(WebConfig(), "127.0.0.1")
    with pytest.raises(ConfigError, match="web.tls_cert"):
        check_exposure(WebConfig(), "0.0.0.0")
    with pytest.raises(ConfigError, match="web.token_file"):
        check_exposure(WebConfig(tls_cert="c.pem", tls_key="k.pem"), "192.168.1.20")
    with pytest.raises(ConfigError, match="web.tls_key"):
        check_exposure(WebConfig(tls_cert="c.pem"), "127.0.0.1")
    short = tmp_path / "t"
    short.write_text("abc\n")
    with pytest.raises(ConfigError, match="web.token_file"):
        read_token(str(short))
    with pytest.raises(ConfigError, match="web.token_file"):
        read_token(str(tmp_path / "missing"))


# -- a live daemon and its page -----------------------------------------------------------------------------


class WebProc:
    """``sa-daemon web`` for ``daemon`` on a free loopback port (``extra_toml`` adds to its config)."""

    def __init__(self, workdir: Path, daemon: DaemonProc, extra_toml: str = "", listen: str | None = None) -> None:
        workdir.mkdir(parents=True, exist_ok=True)
        self.port = free_port()
        self.listen = listen or f"127.0.0.1:{self.port}"
        cfg = workdir / "web.toml"
        cfg.write_text(extra_toml)
        self.log = open(workdir / "web.log", "wb")  # noqa: SIM115
        self.proc = subprocess.Popen([*CLI, "--config", str(cfg), "web", "--listen", self.listen,
                                      "--pub", daemon.pub, "--cmd", daemon.cmd], stdout=self.log, stderr=self.log)
        self.url = f"http://127.0.0.1:{self.port}"

    def wait_listening(self, timeout_s: float = 30.0) -> None:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            assert self.proc.poll() is None, "sa-daemon web exited"
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    return
            time.sleep(0.05)
        raise AssertionError("sa-daemon web is not listening")

    def close(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self.log.close()


@contextlib.contextmanager
def fresh_page(root: Path, method: str = "ho", config: str | None = None):
    """A fresh daemon (by default HO assistance: no questions, the user drives from the start) and its page."""
    d = DaemonProc(root / "daemon", "--method", method, "--duration", "600", "--no-speech", config=config)
    w = WebProc(root / "web", d)
    try:
        d.wait_ready()
        w.wait_listening()
        yield d, w
    finally:
        w.close()
        d.close()


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    """A daemon (simulated user, kinematic arm, early questions) and its page."""
    with fresh_page(tmp_path_factory.mktemp("web"), "policy", DAEMON_TOML) as (d, w):
        yield d, w


async def _ws_messages(url: str, sends: list[str], until, timeout_s: float = 20.0, **kw) -> list[dict]:
    out: list[dict] = []
    async with aiohttp.ClientSession(**kw) as s, s.ws_connect(url) as ws:
        for m in sends:
            await ws.send_str(m)
        end = time.monotonic() + timeout_s
        while not until(out):
            left = end - time.monotonic()
            assert left > 0, f"not seen in {timeout_s} s: {[m['type'] for m in out][-20:]}"
            msg = await ws.receive(timeout=left)
            out.append(json.loads(msg.data))
    return out


def test_the_page_is_served_and_the_websocket_pushes_hello_scene_states_and_events(live):
    _, w = live

    async def run():
        async with aiohttp.ClientSession() as s, s.get(w.url + "/") as r:
            assert r.status == 200 and "sa-daemon" in await r.text()
        return await _ws_messages(w.url + "/ws", [], lambda m: sum(x["type"] == "state" for x in m) >= 20)

    msgs = asyncio.run(run())
    hello = msgs[0]
    assert hello["type"] == "hello" and hello["version"] == 2
    scene = hello["scene"]
    assert scene["name"] == "scene1" and {o["name"] for o in scene["objects"]} == {"cup", "chips can", "bowl"}
    assert {g["target"] for g in scene["goals"]} == {"cup:top", "cup:side", "chips can:side", "bowl:top"}
    states = [m for m in msgs if m["type"] == "state"]
    assert all(abs(sum(b["p"] for b in s["state"]["belief"]) - 1.0) < 1e-9 for s in states)
    ts = [s["state"]["t"] for s in states]
    assert ts == sorted(ts) and (ts[-1] - ts[0]) / (len(ts) - 1) < 1.0 / 20  # at the state rate (30 Hz)
    assert all(abs(s["rx_wall"] - time.time()) < 60 for s in states)


def test_malformed_page_messages_are_refused_with_a_reason_and_never_reach_the_daemon(live):
    d, w = live
    before = d.request({"cmd": "status"})["commands"]
    bad = ["not json", '{"cmd": "launch"}', '{"cmd": "answer", "value": 1}', "[]", '{"cmd": "set_method"}', "x" * 5000]

    async def run():
        msgs = await _ws_messages(w.url + "/ws", bad, lambda m: sum(x["type"] == "refused" for x in m) >= 5)
        async with aiohttp.ClientSession() as s, s.ws_connect(w.url + "/ws") as ws:
            await ws.send_bytes(b"\x00\x01")
            refused = json.loads((await ws.receive(timeout=10)).data)
            while refused["type"] != "refused":
                refused = json.loads((await ws.receive(timeout=10)).data)
        return msgs, refused

    msgs, binary = asyncio.run(run())
    reasons = [m["reason"] for m in msgs if m["type"] == "refused"]
    assert any("not valid JSON" in r for r in reasons) and any("unknown command" in r for r in reasons)
    assert any('"value" must be' in r for r in reasons) and any('"method" must be one of' in r for r in reasons)
    assert "binary" in binary["reason"]
    after = d.request({"cmd": "status"})["commands"]
    assert after["requests"] - before["requests"] <= 2  # the two status requests of this test, nothing else
    assert w.proc.poll() is None  # the page server goes on


def test_stop_and_resume_from_the_page_reach_the_daemon(live):
    d, w = live
    c = d.collector

    async def run(cmd: str) -> list[dict]:
        return await _ws_messages(w.url + "/ws", [json.dumps({"cmd": cmd})],
                                  lambda m: any(x["type"] == "reply" for x in m))

    i = len(c)
    reply = next(m for m in asyncio.run(run("stop")) if m["type"] == "reply")
    assert reply == {"type": "reply", "cmd": "stop", "id": None, "ok": True}
    _, ev = c.event("stop", timeout_s=10, start=i, source="command")
    # a state carries the last control tick's command: the first tick after the latch is within a period
    _, s = c.state(lambda s: s["t"] > ev["t"] + PERIOD_S, start=i)
    assert s["stopped"] and s["command_twist"] == [0.0] * 6
    asyncio.run(run("resume"))
    c.state(lambda s: not s["stopped"], timeout_s=10, start=i)


def test_a_token_guards_every_request(tmp_path, live):
    d, _ = live
    token = "k" * 43
    (tmp_path / "token").write_text(token + "\n")
    w = WebProc(tmp_path / "tok", d, f'[web]\ntoken_file = "{tmp_path / "token"}"\n')
    try:
        w.wait_listening()

        async def run():  # (a browser keeps cookies for an IP address; aiohttp's jar only when "unsafe")
            async with aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as s:
                for path in ("/", "/ws", "/static/app.js", "/?token=wrong"):
                    async with s.get(w.url + path) as r:
                        assert r.status == 401 and await r.read() == b"", path
                async with s.get(w.url + "/?token=" + token) as r:  # once in the address, then the cookie
                    assert r.status == 200
                async with s.ws_connect(w.url + "/ws") as ws:
                    return json.loads((await ws.receive(timeout=10)).data)

        assert asyncio.run(run())["type"] == "hello"
    finally:
        w.close()


def test_a_non_loopback_page_without_tls_is_refused_naming_the_key(tmp_path, live):
    d, _ = live
    r = subprocess.run([*CLI, "web", "--listen", f"0.0.0.0:{free_port()}", "--pub", d.pub, "--cmd", d.cmd],
                       capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 2 and "web.tls_cert" in r.stderr


def test_beyond_loopback_with_tls_and_a_token_the_page_is_served_over_https(tmp_path, live):
    import ssl

    import trustme

    d, _ = live
    ca = trustme.CA()
    cert = ca.issue_cert("127.0.0.1")
    cert.cert_chain_pems[0].write_to_path(str(tmp_path / "cert.pem"))
    cert.private_key_pem.write_to_path(str(tmp_path / "key.pem"))
    r = subprocess.run([*CLI, "keygen", str(tmp_path / "keys"), "--web-token"], capture_output=True, text=True,
                       timeout=60, check=True)
    token_file = tmp_path / "keys" / "web.token"
    assert f'token_file = "{token_file}"' in r.stdout and (token_file.stat().st_mode & 0o777) == 0o600
    token = token_file.read_text().strip()
    toml = (f'[web]\ntls_cert = "{tmp_path / "cert.pem"}"\ntls_key = "{tmp_path / "key.pem"}"\n'
            f'token_file = "{token_file}"\n')
    port = free_port()
    w = WebProc(tmp_path / "tls", d, toml, listen=f"0.0.0.0:{port}")
    w.port = port
    try:
        w.wait_listening()
        ctx = ssl.create_default_context()
        ca.configure_trust(ctx)

        async def run():
            async with aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as s:
                base = f"https://127.0.0.1:{port}"
                async with s.get(base + "/", ssl=ctx) as r:
                    assert r.status == 401
                async with s.get(base + "/?token=" + token, ssl=ctx) as r:
                    assert r.status == 200 and "sa-daemon" in await r.text()
                    assert "Secure" in r.headers["Set-Cookie"] and "HttpOnly" in r.headers["Set-Cookie"]
                async with s.ws_connect(base + "/ws", ssl=ctx) as ws:
                    return json.loads((await ws.receive(timeout=10)).data)

        assert asyncio.run(run())["type"] == "hello"
    finally:
        w.close()


def test_cross_site_websocket_is_refused(live):
    _, w = live

    async def run():
        async with aiohttp.ClientSession() as s:
            with pytest.raises(aiohttp.WSServerHandshakeError) as e:
                await s.ws_connect(w.url + "/ws", headers={"Origin": "https://evil.example"})
            return e.value.status

    assert asyncio.run(run()) == 403


# -- in a real browser -----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def browser():
    if not HAVE_BROWSER:
        pytest.skip(NO_BROWSER)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1280,900"):
        opts.add_argument(a)
    drv = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    try:
        yield drv
    finally:
        drv.quit()


BARS = "return [...document.querySelectorAll('#bars li')].map(li => [li.dataset.goal, +li.dataset.p])"


def test_in_chromium_the_belief_bars_follow_the_user_as_they_drive(browser, tmp_path):
    """A fresh daemon with HO assistance (no questions): the user drives to the cup from the start."""
    with fresh_page(tmp_path) as (_, w):
        browser.get(w.url + "/")
        until(lambda: browser.execute_script("return window.saRendered || 0") > 3, what="states drawn")
        early = dict(browser.execute_script(BARS))
        assert set(early) == {"cup:top", "cup:side", "chips can:side", "bowl:top"}
        late = until(lambda: (b := dict(browser.execute_script(BARS)))["cup:top"] + b["cup:side"]
                 > early["cup:top"] + early["cup:side"] + 0.2 and b, 30, "the cup's bars rising")
        assert late["bowl:top"] < early["bowl:top"]
        order = browser.execute_script("return [...document.querySelectorAll('#bars li')].map(li => li.dataset.goal)")
        assert order[:2] == sorted(late, key=late.get, reverse=True)[:2]  # most likely first


def test_in_chromium_yes_answers_the_question_and_stop_stops(live, browser, tmp_path):
    from selenium.webdriver.common.by import By

    d, w = live
    c = d.collector
    assert d.request({"cmd": "resume"})["ok"]
    browser.get(w.url + "/")
    until(lambda: browser.execute_script("return window.saRendered || 0") > 10, what="states drawn")

    # The daemon asks (its simulated user waits 60 s to answer); the person taps Yes on the page. The
    # question must be one asked from now on: one left pending by an earlier test may time out
    # (runtime.question_timeout_s) between its drawing and the click.
    i = len(c)
    c.event("question", timeout_s=60, start=i)
    until(lambda: (q := c.latest_state()["question"]) and browser.find_element(By.ID, "question").text == q,
          10, "the new question on the page")
    shown = browser.find_element(By.ID, "question").text
    assert browser.find_element(By.ID, "yes").is_enabled()
    shot = tmp_path / "web.png"  # the README's picture: a question waiting for the person
    browser.save_screenshot(str(shot))
    if os.environ.get("SA_WEB_SCREENSHOT"):
        shutil.copy(shot, os.environ["SA_WEB_SCREENSHOT"])
    browser.find_element(By.ID, "yes").click()
    _, ans = c.event("answer", timeout_s=10, start=i)
    assert ans["value"] == "yes" and ans["source"] == "command"
    until(lambda: browser.find_element(By.ID, "question").text != shown, 10, "the question cleared")
    # The person's answer times, as status gives them (the page asks again after each answer).
    times = d.request({"cmd": "status"})["answer_times"]
    until(lambda: browser.find_element(By.ID, "answer-times").text.startswith(f"Answers: {times['count']}, median "),
          10, "the answer times on the page")

    # Stop: latched, and the command is zero from the first control tick after the latch.
    i = len(c)
    t_click = time.monotonic()
    browser.find_element(By.ID, "stop").click()
    ie, ev = c.event("stop", timeout_s=10, start=i, source="command")
    seen_s = next(at for at, m in c.received(i) if m.get("type") == "stop") - t_click
    _, s = c.state(lambda s: s["t"] > ev["t"] + PERIOD_S, start=ie)
    assert s["stopped"] and s["command_twist"] == [0.0] * 6
    until(lambda: "STOPPED" in browser.find_element(By.ID, "stopped").text, 10, "the page shows the stop")
    lat = sorted(browser.execute_script("return window.saLatency"))
    median_ms, p95_ms = 1e3 * lat[len(lat) // 2], 1e3 * lat[int(0.95 * (len(lat) - 1))]
    print(f"page: state -> pixels median {median_ms:.1f} ms, p95 {p95_ms:.1f} ms over {len(lat)} states; "
          f"click -> stop latched, as a subscriber sees it, {seen_s * 1e3:.1f} ms")
    assert median_ms < 200 and seen_s < 1.0
    assert d.request({"cmd": "resume"})["ok"]


def test_in_chromium_the_keyboard_works_too(live, browser):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    d, w = live
    c = d.collector
    browser.get(w.url + "/")
    until(lambda: browser.execute_script("return window.saRendered || 0") > 3, what="states drawn")
    i = len(c)
    browser.find_element(By.TAG_NAME, "body").send_keys("s")
    c.event("stop", timeout_s=10, start=i, source="command")
    browser.find_element(By.ID, "resume").send_keys(Keys.ENTER)  # focus a button, press Enter
    c.event("resume", timeout_s=10, start=i)


def test_in_chromium_the_page_says_in_words_why_the_robot_holds_back(live, browser):
    """The state's ``yielding`` (docs/protocol.md) drawn by the page: the live daemon's last state, and the
    same state with each reason the controller gives (set in the page, drawn by its own render)."""
    from selenium.webdriver.common.by import By

    _, w = live
    browser.get(w.url + "/")
    until(lambda: browser.execute_script("return window.saRendered || 0") > 3, what="states drawn")
    assert "held back" not in browser.find_element(By.ID, "action").text  # the simulated user does not churn
    drawn = {reason: browser.execute_script(
        "render({...last, yielding: arguments[0]}); return document.getElementById('action').textContent", reason)
        for reason in ("mode_churn", "user_opposes", "near_object", "a_future_reason")}
    assert drawn["mode_churn"].endswith(", held back: you keep switching mode")
    assert drawn["user_opposes"].endswith(", held back: you keep pushing against it")
    assert drawn["near_object"].endswith(", held back: near the object, you finish the grasp")
    assert drawn["a_future_reason"].endswith(", held back: a_future_reason")  # an unknown reason as sent


def test_in_chromium_a_bad_token_gets_nothing_and_the_right_one_the_live_page(live, browser, tmp_path):
    d, _ = live
    token = "t" * 43
    (tmp_path / "token").write_text(token)
    w = WebProc(tmp_path / "tok", d, f'[web]\ntoken_file = "{tmp_path / "token"}"\n')
    try:
        w.wait_listening()
        browser.delete_all_cookies()
        browser.get(w.url + "/?token=wrong")
        assert browser.title != "sa-daemon" and "STOP" not in browser.page_source  # an empty 401
        browser.get(w.url + "/?token=" + token)
        assert browser.title == "sa-daemon"
        until(lambda: browser.execute_script("return window.saRendered || 0") > 3, what="states over the WebSocket")
        browser.get(w.url + "/")  # the cookie alone, from now on
        until(lambda: browser.execute_script("return window.saRendered || 0") > 3, what="states with the cookie")
    finally:
        w.close()


def test_in_chromium_the_page_says_when_the_daemon_goes_quiet(browser, tmp_path):
    from selenium.webdriver.common.by import By

    with fresh_page(tmp_path) as (d, w):
        browser.get(w.url + "/")
        until(lambda: browser.find_element(By.ID, "link").text == "live", 30, "live")
        d.close()  # the daemon ends: no more states
        until(lambda: "stale" in browser.find_element(By.ID, "link").text, 10, "the view marked stale")
