"""Fixtures for the security tests: a throwaway CA and certificates made at test time with
configs/security/make-certs.sh (openssl), and the real service over TLS on 127.0.0.1."""

from __future__ import annotations

import shutil
import subprocess
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import msgspec
import pytest

from fusion import messages as m
from fusion.config import AccessControlConfig, ServiceConfig, TlsConfig, ZenohConfig
from fusion.io.zenoh_bus import free_tcp_port, zenoh_json, zenoh_session_config
from fusion.service import Service

MAKE_CERTS = Path(__file__).resolve().parents[2] / "configs" / "security" / "make-certs.sh"
# CN of every client certificate made for the tests; "stranger" is signed by the CA but named in
# no access-control role.
CLIENTS = ("sensor-cam1", "sensor-radar1", "input-control", "simulator", "viewer", "recorder", "stranger")


class Certs:
    """Paths of the certificates in `root` (as make-certs.sh writes them)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.ca = root / "ca.pem"

    def cert(self, name: str) -> Path:
        return self.root / f"{name}.pem"

    def key(self, name: str) -> Path:
        return self.root / f"{name}-key.pem"

    def tls(self, name: str | None, *, require_client_certificate: bool = False) -> TlsConfig:
        """[zenoh.tls] trusting this CA, with `name`'s certificate (None: no certificate)."""
        return TlsConfig(root_ca=str(self.ca), certificate=str(self.cert(name)) if name else "",
                         private_key=str(self.key(name)) if name else "",
                         require_client_certificate=require_client_certificate)


def _make(root: Path, *names: str) -> Certs:
    subprocess.run(["sh", str(MAKE_CERTS), str(root), *names], check=True, capture_output=True, timeout=60)
    return Certs(root)


@pytest.fixture(scope="session")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Certs:
    """A CA, the service's certificate and one client certificate per name of CLIENTS."""
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed: the TLS tests make their certificates with it")
    return _make(tmp_path_factory.mktemp("certs"), *CLIENTS)


@pytest.fixture(scope="session")
def other_certs(tmp_path_factory: pytest.TempPathFactory, certs: Certs) -> Certs:
    """Another CA, with a certificate named like a trusted one: not to be trusted."""
    return _make(tmp_path_factory.mktemp("other-ca"), "sensor-cam1")


def service_zenoh(certs: Certs, endpoint: str, *, access_control: AccessControlConfig | None = None,
                  require_client_certificate: bool = True) -> ZenohConfig:
    return ZenohConfig(mode="peer", listen=[endpoint], access_control=access_control,
                       tls=certs.tls("fusion-service", require_client_certificate=require_client_certificate))


@contextmanager
def tls_service(cfg: ServiceConfig, certs: Certs, tmp: Path, *, access_control: AccessControlConfig | None = None,
                require_client_certificate: bool = True) -> Iterator[tuple[Service, str]]:
    """The real service on tls/127.0.0.1:<free port>, run in a thread; stopped on exit."""
    for _ in range(20):
        endpoint = f"tls/127.0.0.1:{free_tcp_port()}"
        zc = service_zenoh(certs, endpoint, access_control=access_control,
                           require_client_certificate=require_client_certificate)
        svc = Service(msgspec.structs.replace(cfg, zenoh=zc), recording_path=tmp / "live.rrd",
                      stream_path=tmp / "live.fstream")
        try:
            svc.open()
            break
        except Exception as e:  # another process took the port between probe and bind: try another
            if "in use" not in str(e).lower():
                raise
    else:
        raise RuntimeError("no free loopback port for the service")
    t = threading.Thread(target=svc.run, name="tls-service-under-test")
    t.start()
    try:
        yield svc, endpoint
    finally:
        svc.stop()
        t.join(timeout=60)
        assert not t.is_alive(), "the service did not stop"


@pytest.fixture
def tls_client() -> Iterator[Callable[..., Any]]:
    """open(endpoint, tls) -> a client session over TLS; every one closed in teardown."""
    import zenoh

    opened: list[Any] = []

    def make(endpoint: str, tls: TlsConfig) -> Any:
        s = zenoh.open(zenoh_session_config(ZenohConfig(mode="client", listen=[], connect=[endpoint], tls=tls)))
        opened.append(s)
        return s

    try:
        yield make
    finally:
        for s in reversed(opened):
            s.close()


def cam1_measurement(seq: int, *, big: bool = False) -> bytes:
    """cam1's measurement `seq` (every 0.2 s); `big` (a covariance given) makes it larger than
    any of the others, so a size filter (lossy_client) drops it."""
    return m.encode(m.Measurement(sensor_id="cam1", t_ns=seq * 200_000_000, seq=seq, data=m.Cartesian(
        pos_m=[100.0 + seq, 0.0], cov_m2=[1.0, 0.0, 0.0, 1.0] if big else None)))


def lossy_client(certs: Certs, endpoint: str, name: str, ns: str) -> Any:
    """A client session with `name`'s certificate that drops, as they leave it, its puts on
    fusion/<ns>/meas/** larger than cam1_measurement(seq) for seq < 10 (zenoh's low-pass filter):
    the network losing chosen samples. The caller closes it."""
    import json

    import zenoh

    conf = zenoh_json(ZenohConfig(mode="client", listen=[], connect=[endpoint], tls=certs.tls(name)))
    small = max(len(cam1_measurement(s)) for s in range(10))
    conf["low_pass_filter"] = [{"flows": ["egress"], "messages": ["put"], "key_exprs": [f"fusion/{ns}/meas/**"],
                                "size_limit": small}]
    return zenoh.open(zenoh.Config.from_json5(json.dumps(conf)))
