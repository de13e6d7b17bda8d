"""The service as a Zenoh client: the peer down at start (retry with backoff, then a clear
error), the peer going away and coming back (reconnects, said in status)."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import msgspec

from fusion import messages as m
from fusion.cli.runner import Exit
from fusion.config import ZenohConfig
from fusion.io.zenoh_bus import free_tcp_port, session_config
from fusion.service import Service
from tests.cli.helpers import run
from tests.service.harness import client, query, scenario_config

ROOT = Path(__file__).resolve().parents[2]


def test_serve_in_client_mode_with_no_peer_says_what_it_needs(tmp_path: Path) -> None:
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    text = (ROOT / "configs" / "service.toml").read_text().replace("[zenoh]\n", "[zenoh]\nconnect_retry_s = 1.0\n", 1)
    (tmp_path / "s.toml").write_text(text)
    t0 = time.monotonic()
    r = run("fusion", "serve", "-c", "s.toml", "-m", "client", "-e", ep, "--recordings", str(tmp_path / "rec"),
            cwd=tmp_path)
    took = time.monotonic() - t0
    assert r.returncode == Exit.CONNECT, r.stderr
    assert "Traceback" not in r.stderr
    line = r.stderr.strip().splitlines()[-1]  # after the retry warnings, one error line
    assert line.startswith("fusion serve: error: ")
    assert f"cannot connect to {ep}: nothing is listening there; in client mode the service needs a Zenoh router " \
           "or peer" in line, line
    assert "start the service first" not in line
    assert "retrying in 0.25 s" in r.stderr and "retrying in 0.50 s" in r.stderr, "no backoff before giving up"
    assert took < 30.0
    assert not (tmp_path / "rec").exists() or not list((tmp_path / "rec").iterdir()), "files left behind"


def test_a_client_service_waits_for_its_peer_and_reconnects(tmp_path: Path) -> None:
    import zenoh

    _, cfg = scenario_config("radar2d")
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    cfg = msgspec.structs.replace(cfg, zenoh=ZenohConfig(mode="client", connect=[ep], connect_retry_s=20.0))
    svc = Service(cfg, recording_path=tmp_path / "c.rrd", stream_path=tmp_path / "c.fstream")
    hub: list = []
    threading.Timer(1.5, lambda: hub.append(zenoh.open(session_config(mode="peer", listen=[ep])))).start()
    t = threading.Thread(target=svc.run)  # run() opens: retrying until the hub is up
    t.start()
    try:
        deadline = time.monotonic() + 20
        while not svc.status_dict().get("link") and time.monotonic() < deadline:
            time.sleep(0.05)
        st = svc.status_dict()["link"]
        assert st["connected"] and st["connect_attempts"] >= 3, st
        hub.pop().close()
        while svc.status_dict()["link"]["connected"] and time.monotonic() < deadline + 10:
            time.sleep(0.1)
        assert svc.status_dict()["link"]["disconnects"] == 1
        hub.append(zenoh.open(session_config(mode="peer", listen=[ep])))
        s = client(ep)
        try:
            end = time.monotonic() + 15
            status = None
            while time.monotonic() < end:
                try:
                    status = m.decode_status(query(s, m.status_key(cfg.namespace)))
                    if status.link is not None and status.link.reconnects == 1:
                        break
                except AssertionError:  # no reply yet: the service has not reconnected
                    pass
                time.sleep(0.2)
        finally:
            s.close()
        assert status is not None and status.link is not None
        assert status.link.connected and status.link.reconnects == 1 and status.link.disconnects == 1
    finally:
        svc.stop()
        t.join(timeout=60)
        for h in hub:
            h.close()
    assert not t.is_alive()
