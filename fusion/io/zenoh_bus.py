"""Zenoh sessions on safe defaults: loopback listeners, no multicast or gossip scouting.

A peer must always name its listen endpoints (the default listens on every interface), and a
listen endpoint off loopback is refused unless the configuration says `allow_remote`. The spokes
of a peer hub must be clients: peers do not forward for other peers. With [zenoh.tls] every link
is TLS (only the `tls` protocol is accepted); with [zenoh.access_control] the node enforces
fusion's roles (see fusion/io/zenoh_acl.py and SECURITY.md).
"""

from __future__ import annotations

import ipaddress
import json
import logging
import socket
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import msgspec

from fusion.config import Section, ZenohConfig
from fusion.errors import ConfigError
from fusion.io.zenoh_acl import access_control_section

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
LOCAL_PROTOCOLS = ("unixsock-stream", "unixpipe")  # no network address at all

log = logging.getLogger("fusion.zenoh")


def session_config(*, mode: str = "peer", listen: Sequence[str] = (DEFAULT_ENDPOINT,),
                   connect: Sequence[str] = ()) -> Any:
    """A zenoh.Config: a peer listening on `listen`, or a client connecting to `connect`
    (plain links, loopback listeners only); `zenoh_session_config` takes the whole section."""
    if mode not in ("peer", "client"):
        raise ConfigError(f"zenoh mode must be 'peer' or 'client', got {mode!r}")
    return zenoh_session_config(ZenohConfig(mode=mode, listen=list(listen), connect=list(connect)))  # type: ignore[arg-type]


def zenoh_session_config(zc: ZenohConfig, *, namespace: str | None = None) -> Any:
    """A zenoh.Config from a [zenoh] section (`namespace` is needed for access control)."""
    import zenoh

    return zenoh.Config.from_json5(json.dumps(zenoh_json(zc, namespace=namespace)))


def zenoh_json(zc: ZenohConfig, *, namespace: str | None = None) -> dict[str, Any]:
    """The zenoh configuration (a JSON-able dict) for `zc`, after every check: a peer names its
    listen endpoints, all on loopback unless allow_remote; a client names connect endpoints;
    with TLS every endpoint is tls/ and the files exist; access control needs a listening peer
    with client certificates required."""
    scouting: dict[str, Any] = {"multicast": {"enabled": False}, "gossip": {"enabled": False}}
    conf: dict[str, Any] = {"mode": zc.mode, "scouting": scouting}
    listen = list(zc.listen) if zc.mode == "peer" else []
    if zc.mode == "peer":
        if not listen:
            raise ConfigError("a peer must name its listen endpoints (the default would listen on every interface)")
        if not zc.allow_remote:
            for ep in listen:
                if not is_local_endpoint(ep):
                    raise ConfigError(f"listen endpoint {ep!r} is reachable from other machines; set "
                                      "[zenoh] allow_remote = true to mean it (and use [zenoh.tls])")
        elif zc.tls is None and not all(is_local_endpoint(ep) for ep in listen):
            log.warning("zenoh listens off loopback without TLS: anyone who can reach %s can publish and read",
                        listen)
        conf["listen"] = {"endpoints": listen}
        scouting["delay"] = 0
    elif not zc.connect:
        raise ConfigError("a client needs at least one connect endpoint")
    if zc.connect:
        conf["connect"] = {"endpoints": list(zc.connect), "retry": {
            "period_init_ms": 100, "period_max_ms": round(zc.retry_max_s * 1000), "period_increase_factor": 2}}
    if zc.tls is not None:
        conf["transport"] = {"link": {"protocols": ["tls"], "tls": _tls_json(zc, listen)}}
    if zc.access_control is not None:
        if zc.mode != "peer":
            raise ConfigError("[zenoh.access_control] is enforced by the node others connect to: the service must be "
                              "a listening peer (with a router, put the rules in the router's configuration)")
        if zc.tls is None or not zc.tls.require_client_certificate:
            raise ConfigError("[zenoh.access_control] identifies clients by their TLS certificate: it needs "
                              "[zenoh.tls] with require_client_certificate = true")
        if namespace is None:
            raise ConfigError("[zenoh.access_control] needs the namespace its keys are in")
        conf["access_control"] = access_control_section(zc.access_control, namespace=namespace)
    return conf


def _tls_json(zc: ZenohConfig, listen: list[str]) -> dict[str, Any]:
    tls = zc.tls
    assert tls is not None
    for ep in [*listen, *zc.connect]:
        if not ep.startswith("tls/"):
            raise ConfigError(f"with [zenoh.tls] every endpoint must be tls/HOST:PORT, got {ep!r}")
    if not listen and tls.require_client_certificate:
        raise ConfigError("[zenoh.tls] require_client_certificate is for a listening peer; a client presents "
                          "its certificate whenever it has one")
    if listen and not (tls.certificate and tls.private_key):
        raise ConfigError("[zenoh.tls] a listening peer needs its certificate and private_key")
    if bool(tls.certificate) != bool(tls.private_key):
        raise ConfigError("[zenoh.tls] certificate and private_key go together")
    for what, path in (("root_ca", tls.root_ca), ("certificate", tls.certificate), ("private_key", tls.private_key)):
        if path and not Path(path).is_file():
            raise ConfigError(f"[zenoh.tls] {what}: no file at {path!r} (relative to {Path.cwd()})")
    out: dict[str, Any] = {"root_ca_certificate": tls.root_ca}
    if tls.certificate:
        # Zenoh presents a client certificate only with enable_mtls, which on a listener also
        # demands one from every client: a client presents its certificate whenever it has one.
        out.update(listen_certificate=tls.certificate, listen_private_key=tls.private_key,
                   connect_certificate=tls.certificate, connect_private_key=tls.private_key)
    out["enable_mtls"] = tls.require_client_certificate if listen else bool(tls.certificate)
    return out


def is_local_endpoint(endpoint: str) -> bool:
    """True for an endpoint only this machine can reach: loopback addresses (127.0.0.0/8, ::1,
    localhost) and unix sockets. `proto/host:port?metadata#config` as zenoh writes them."""
    proto, sep, rest = endpoint.partition("/")
    if not sep:
        return False
    if proto in LOCAL_PROTOCOLS:
        return True
    addr = rest.split("?", 1)[0].split("#", 1)[0]
    host = addr.rsplit(":", 1)[0] if ":" in addr else addr
    host = host.strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _ZenohFile(Section):
    zenoh: ZenohConfig


def load_zenoh_file(path: str | Path) -> ZenohConfig:
    """The [zenoh] table of a TOML file (e.g. configs/security/sensor-client.toml): how a
    command-line tool joins Zenoh, with its TLS files and identity."""
    try:
        return msgspec.toml.decode(Path(path).read_bytes(), type=_ZenohFile).zenoh
    except OSError as e:
        raise ConfigError(f"cannot read zenoh configuration {path}: {e}") from e
    except msgspec.DecodeError as e:  # ValidationError included
        raise ConfigError(f"invalid zenoh configuration {path}: {e}") from e


def cli_zenoh_config(*, zenoh_file: str | Path | None = None, listen: Sequence[str] | None = None,
                     connect: Sequence[str] | None = None) -> ZenohConfig:
    """How a command-line tool (fusion-publish, fusion record) joins Zenoh: the [zenoh] table
    of `zenoh_file` (TLS, identity), else a client of DEFAULT_ENDPOINT; `listen` makes it a peer
    listening there, `connect` replaces the connect endpoints."""
    base = load_zenoh_file(zenoh_file) if zenoh_file is not None else ZenohConfig(mode="client", listen=[],
                                                                                 connect=[DEFAULT_ENDPOINT])
    if listen:
        base = msgspec.structs.replace(base, mode="peer", listen=list(listen),
                                       connect=list(connect) if connect else [])
    elif connect:
        base = msgspec.structs.replace(base, connect=list(connect))
    return base


def open_with_retry(zc: ZenohConfig, *, namespace: str | None = None,
                    stop: threading.Event | None = None) -> tuple[Any, int]:
    """(session, attempts): zenoh.open, retried while a client finds nothing to connect to, for
    at most zc.connect_wait_s, waiting 0.1 s, 0.2 s, ... (at most zc.retry_max_s) between tries;
    each failure is logged. Other errors, and the last failure, are raised. (None, attempts)
    when `stop` is set while waiting."""
    import zenoh

    conf_json = json.dumps(zenoh_json(zc, namespace=namespace))
    deadline = time.monotonic() + zc.connect_wait_s
    wait_s, attempts = 0.1, 0
    while True:
        attempts += 1
        try:
            return zenoh.open(zenoh.Config.from_json5(conf_json)), attempts
        except zenoh.ZError as e:
            left = deadline - time.monotonic()
            if zc.mode != "client" or "Unable to connect" not in str(e) or left <= 0:
                raise
            wait_s = min(wait_s, left)
            log.info("connecting: nothing listens at %s yet (attempt %d); retrying in %.1f s, for %.0f s more",
                        ", ".join(zc.connect), attempts, wait_s, left)
            if stop is not None and stop.wait(wait_s):
                return None, attempts
            if stop is None:
                time.sleep(wait_s)
            wait_s = min(wait_s * 2, zc.retry_max_s)


def connection_of(session: Any) -> tuple[int, int]:
    """(routers, peers) the session is connected to right now."""
    return len(list(session.info.routers_zid())), len(list(session.info.peers_zid()))


class Link:
    """How a service's session is joined, as its status reports it: a peer is "listening"; a
    client "connected" or "disconnected" (zenoh reconnects by itself; each return is counted, and
    each change logged, when `report` sees it)."""

    def __init__(self, zc: ZenohConfig) -> None:
        self._zc = zc
        self.connect_attempts = 0  # of the session's opening (open_with_retry)
        self._linked = True  # a client: connected to its peer or router when last looked
        self._reconnects = 0

    def report(self, session: Any) -> dict[str, Any]:
        routers, peers = connection_of(session) if session is not None else (0, 0)
        mode = self._zc.mode
        if mode == "client":
            linked = routers + peers > 0
            if linked and not self._linked:
                self._reconnects += 1
                log.warning("zenoh: connected again to %s", ", ".join(self._zc.connect))
            elif self._linked and not linked and session is not None:
                log.warning("zenoh: lost the connection to %s; reconnecting", ", ".join(self._zc.connect))
            self._linked = linked
            state = "connected" if linked else "disconnected"
        else:
            state = "listening"
        return {"mode": mode, "state": state, "routers": routers, "peers": peers,
                "connect_attempts": self.connect_attempts, "reconnects": self._reconnects}


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
