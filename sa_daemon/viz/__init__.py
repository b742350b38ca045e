"""The live 3-D view for the tools researchers use (Foxglove; ``docs/foxglove.md``).

Data flows left to right: :mod:`.messages` turns the daemon's documented protocol messages (the
``scene`` reply, ``state``, events) into Foxglove messages; :mod:`.feed` decides which to send when
and hands them to its sinks (the live WebSocket server of :mod:`.live`, and the MCAP recorder), so a
recording and a live run carry the same topics with the same schemas.
"""
