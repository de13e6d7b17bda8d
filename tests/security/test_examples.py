"""The documented example of configs/security/ works as SECURITY.md says: certificates from
make-certs.sh in ./certs, the service from service-tls.toml, and its clients from their files
(through cli_zenoh_config, as `fusion-publish --zenoh-config FILE --connect ...` does). Only
the port changes, to a free one on 127.0.0.1."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgspec
import pytest

from fusion import messages as m
from fusion.config import load_service_config
from fusion.io.zenoh_bus import cli_zenoh_config, free_tcp_port, load_zenoh_file, zenoh_session_config
from fusion.service import Service
from publishers.publish import publish
from publishers.stream import build_stream
from tests.security.conftest import Certs
from tests.service.harness import scenario_config

EXAMPLES = Path(__file__).resolve().parents[2] / "configs" / "security"
CLIENT_FILES = ("sensor-cam1", "simulator", "viewer", "recorder")


@pytest.fixture
def in_example_dir(certs: Certs, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A working directory whose certs/ holds the test certificates, as the example expects."""
    (tmp_path / "certs").symlink_to(certs.root, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    yield tmp_path


def test_example_files_load(in_example_dir: Path) -> None:
    cfg = load_service_config(EXAMPLES / "service-tls.toml")
    zc = cfg.zenoh
    assert zc.tls is not None and zc.tls.require_client_certificate and zc.access_control is not None
    assert zc.listen == ["tls/127.0.0.1:7447"] and not zc.allow_remote
    assert sorted(zc.access_control.sensors) == sorted(s.id for s in cfg.tracker.sensors)
    zenoh_session_config(zc, namespace=cfg.namespace)  # every check passes, zenoh accepts the result
    for name in CLIENT_FILES:
        c = load_zenoh_file(EXAMPLES / f"{name}.toml")
        assert c.mode == "client" and c.connect == zc.listen and c.tls is not None
        assert c.tls.certificate == f"certs/{name}.pem"
        zenoh_session_config(c)


def test_example_service_with_its_clients(in_example_dir: Path) -> None:
    cfg = load_service_config(EXAMPLES / "service-tls.toml")
    endpoint = f"tls/127.0.0.1:{free_tcp_port()}"
    cfg = msgspec.structs.replace(cfg, zenoh=msgspec.structs.replace(cfg.zenoh, listen=[endpoint]))
    svc = Service(cfg, recording_path=in_example_dir / "live.rrd", stream_path=in_example_dir / "live.fstream")
    svc.open()
    runner = threading.Thread(target=svc.run, name="example-service")
    runner.start()
    import zenoh

    sessions: list[Any] = []

    def client(name: str) -> Any:
        zc = cli_zenoh_config(zenoh_file=EXAMPLES / f"{name}.toml", connect=[endpoint])
        sessions.append(zenoh.open(zenoh_session_config(zc)))
        return sessions[-1]

    try:
        spec, _ = scenario_config("mix")
        samples, _ = build_stream(msgspec.structs.replace(spec, duration_s=3.0), namespace=cfg.namespace)
        got: list[str] = []
        client("viewer").declare_subscriber(m.all_tracks_key(cfg.namespace), lambda s: got.append(str(s.key_expr)))
        time.sleep(0.3)
        publish(client("simulator"), samples, speed=0.0, match_timeout_s=5.0)
        assert svc.wait_idle(timeout_s=60.0)
        deadline = time.monotonic() + 5.0
        while len(got) < svc.published and time.monotonic() < deadline:
            time.sleep(0.01)
        counts = svc.status_dict()["counts"]
    finally:
        for s in sessions:
            s.close()
        svc.stop()
        runner.join(timeout=60)
    assert counts["received"] == len(samples)  # measurements and truth
    assert len(got) == svc.published > 0
