"""``sa-daemon web``: the page for the carer and the researcher (``docs/web.md``), a client of the ZeroMQ protocol."""
