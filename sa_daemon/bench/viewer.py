"""A Foxglove viewer for ``bench loop --foxglove``: one WebSocket client, in a spawned process, that
subscribes to every channel the live view advertises and counts what arrives (it does not decode: the
load on the daemon is the sending).

Figures: messages and bytes per topic, and the longest gap between two ``/belief`` messages (they
accompany every ``state`` message, so a gap is the live view falling behind the publish loop).
"""

from __future__ import annotations

import asyncio
import struct
import time
from multiprocessing.connection import Connection
from typing import Any

from .load import LoadProcess

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 1


async def _view(url: str, ready: Any, stop: Any) -> dict[str, Any]:
    import aiohttp

    counts: dict[str, list[int]] = {}
    last_belief, max_gap = 0.0, 0.0
    async with aiohttp.ClientSession() as http, http.ws_connect(url, protocols=(SUBPROTOCOL,)) as ws:
        topics: dict[int, str] = {}
        while len(topics) < 3:
            msg = await ws.receive_json(timeout=10)
            if msg["op"] == "advertise":
                topics.update({c["id"]: c["topic"] for c in msg["channels"]})
        subs = {i: topic for i, topic in enumerate(topics.values())}
        await ws.send_json({"op": "subscribe", "subscriptions": [{"id": i, "channelId": cid}
                                                                 for i, cid in enumerate(topics)]})
        ready.set()
        while not stop.is_set():
            try:
                m = await ws.receive(timeout=0.1)
            except TimeoutError:
                continue
            if m.type != aiohttp.WSMsgType.BINARY or m.data[0] != MESSAGE_DATA:
                if m.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.ERROR):
                    break
                continue
            topic = subs[struct.unpack_from("<I", m.data, 1)[0]]
            c = counts.setdefault(topic, [0, 0])
            c[0] += 1
            c[1] += len(m.data) - 13
            if topic == "/belief":
                now = time.monotonic()
                if last_belief:
                    max_gap = max(max_gap, now - last_belief)
                last_belief = now
    return {"messages": {t: c[0] for t, c in counts.items()}, "bytes": {t: c[1] for t, c in counts.items()},
            "belief_gap_ms_max": round(1e3 * max_gap, 1)}


def _viewer_main(url: str, ready: Any, stop: Any, out: Connection) -> None:
    try:
        figs = asyncio.run(_view(url, ready, stop))
    except Exception as e:  # noqa: BLE001 - reported in the figures
        figs = {"error": f"{type(e).__name__}: {e}"}
        ready.set()
    out.send(figs)


class FoxgloveViewer(LoadProcess):
    """One Foxglove client of ``url`` subscribed to every channel, in a spawned process; :meth:`stop`
    returns its figures (module doc)."""

    def __init__(self, url: str) -> None:
        super().__init__(_viewer_main, (url,), "sa-bench-foxglove-viewer")
