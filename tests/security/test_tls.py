"""The service and a publisher over TLS on 127.0.0.1, with client certificates required: data
flows between holders of certificates from the service's CA; everyone else is refused at open."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import pytest

from fusion import messages as m
from fusion.config import TlsConfig, ZenohConfig
from fusion.io.zenoh_bus import zenoh_session_config
from publishers.publish import publish
from publishers.stream import build_stream
from tests.security.conftest import Certs, tls_service
from tests.service.harness import EstimateCollector, scenario_config


def _refused(zc: ZenohConfig) -> str:
    import zenoh

    with pytest.raises(zenoh.ZError) as e:
        s = zenoh.open(zenoh_session_config(zc))
        s.close()
    return str(e.value)


def test_service_and_publisher_over_mutual_tls(certs: Certs, tmp_path: Path, tls_client: Callable[..., Any]) -> None:
    spec, cfg = scenario_config("mix")
    spec = msgspec.structs.replace(spec, duration_s=5.0)
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    n_meas = sum(1 for s in samples if "/meas/" in s.key)
    with tls_service(cfg, certs, tmp_path) as (svc, endpoint):
        assert endpoint.startswith("tls/127.0.0.1:")
        col = EstimateCollector(tls_client(endpoint, certs.tls("viewer")), cfg.namespace)
        counts = publish(tls_client(endpoint, certs.tls("simulator")), samples, speed=0.0, match_timeout_s=5.0)
        assert svc.wait_idle(timeout_s=60.0)
        deadline = time.monotonic() + 5.0
        while len(col.snapshot()) < svc.published and time.monotonic() < deadline:
            time.sleep(0.01)
        st = svc.status_dict()["counts"]
        viewer = tls_client(endpoint, certs.tls("viewer"))
        replies = list(viewer.get(m.status_key(cfg.namespace), timeout=5.0))
    assert counts["meas"] == n_meas
    assert st["received"] == len(samples) and st["applied"] + st["duplicates"] == n_meas
    assert len(col.snapshot()) == svc.published > 0
    assert len(replies) == 1 and m.decode_status(replies[0].ok.payload.to_bytes()).counts.received == len(samples)


@pytest.mark.parametrize("who", ["no certificate", "certificate from another CA", "does not trust the service's CA",
                                 "plain tcp"], ids=str)
def test_clients_without_a_certificate_from_the_ca_are_refused(
        who: str, certs: Certs, other_certs: Certs, tmp_path: Path, tls_client: Callable[..., Any]) -> None:
    _, cfg = scenario_config("mix")
    with tls_service(cfg, certs, tmp_path) as (_, endpoint):
        tls_client(endpoint, certs.tls("sensor-cam1"))  # the control: a good certificate connects
        if who == "no certificate":
            zc = ZenohConfig(mode="client", listen=[], connect=[endpoint], tls=certs.tls(None))
        elif who == "certificate from another CA":  # same CN, and it trusts the right CA
            zc = ZenohConfig(mode="client", listen=[], connect=[endpoint], tls=TlsConfig(
                root_ca=str(certs.ca), certificate=str(other_certs.cert("sensor-cam1")),
                private_key=str(other_certs.key("sensor-cam1"))))
        elif who == "does not trust the service's CA":
            zc = ZenohConfig(mode="client", listen=[], connect=[endpoint], tls=other_certs.tls("sensor-cam1"))
        else:
            zc = ZenohConfig(mode="client", listen=[], connect=["tcp/" + endpoint.removeprefix("tls/")])
        assert "Unable to connect" in _refused(zc)


def test_server_only_tls_accepts_clients_without_certificates(certs: Certs, other_certs: Certs, tmp_path: Path,
                                                              tls_client: Callable[..., Any]) -> None:
    """require_client_certificate = false: encryption and the service's identity only."""
    _, cfg = scenario_config("mix")
    with tls_service(cfg, certs, tmp_path, require_client_certificate=False) as (_, endpoint):
        s = tls_client(endpoint, certs.tls(None))
        replies = list(s.get(m.status_key(cfg.namespace), timeout=5.0))
        assert len(replies) == 1 and replies[0].ok is not None
        # a client still refuses a service whose certificate its CA did not sign
        zc = ZenohConfig(mode="client", listen=[], connect=[endpoint], tls=other_certs.tls(None))
        assert "Unable to connect" in _refused(zc)
