"""Zenoh sessions on safe defaults: loopback listeners, no multicast or gossip scouting.

A peer must always name its listen endpoints (the default listens on every interface), and the
spokes of a peer hub must be clients: peers do not forward for other peers.
"""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Sequence
from typing import Any

from fusion.errors import ConfigError

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


def session_config(*, mode: str = "peer", listen: Sequence[str] = (DEFAULT_ENDPOINT,),
                   connect: Sequence[str] = ()) -> Any:
    """A zenoh.Config: a peer listening on `listen`, or a client connecting to `connect`."""
    import zenoh

    scouting: dict[str, Any] = {"multicast": {"enabled": False}, "gossip": {"enabled": False}}
    conf: dict[str, Any] = {"mode": mode, "scouting": scouting}
    if mode == "peer":
        if not listen:
            raise ConfigError("a peer must name its listen endpoints (the default would listen on every interface)")
        conf["listen"] = {"endpoints": list(listen)}
        scouting["delay"] = 0
    elif mode == "client":
        if not connect:
            raise ConfigError("a client needs at least one connect endpoint")
    else:
        raise ConfigError(f"zenoh mode must be 'peer' or 'client', got {mode!r}")
    if connect:
        conf["connect"] = {"endpoints": list(connect)}
    return zenoh.Config.from_json5(json.dumps(conf))


def free_tcp_port() -> int:
    """A TCP port free on 127.0.0.1 right now (bind to port 0, read it, close)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_for_match(publisher: Any, *, timeout_s: float) -> bool:
    """Wait until a subscriber matches `publisher` (puts before that can be lost); True if it did."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if publisher.matching_status.matching:
            return True
        time.sleep(0.001)
    return bool(publisher.matching_status.matching)
