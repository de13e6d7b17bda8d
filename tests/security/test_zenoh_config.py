"""The zenoh configuration fusion builds: loopback by default, remote listeners only when asked,
TLS on every link when configured, access control only where it can work. No session is opened
here except where a test says so; nothing listens off loopback."""

from __future__ import annotations

from pathlib import Path

import msgspec
import pytest

from fusion.config import AccessControlConfig, TlsConfig, ZenohConfig, decode_service_config, load_service_config
from fusion.errors import ConfigError
from fusion.io.zenoh_acl import access_control_section, mismatches
from fusion.io.zenoh_bus import (
    DEFAULT_ENDPOINT,
    cli_zenoh_config,
    is_local_endpoint,
    load_zenoh_file,
    session_config,
    zenoh_json,
    zenoh_session_config,
)
from tests.security.conftest import Certs

ROOT = Path(__file__).resolve().parents[2]
LOCAL = ["tcp/127.0.0.1:7447", "tcp/127.3.4.5:1", "tcp/[::1]:7447", "tcp/localhost:7447", "tls/localhost:7447",
         "udp/127.0.0.1:7447", "tls/127.0.0.1:7447#iface=lo", "unixsock-stream//tmp/fusion.sock"]
REMOTE = ["tcp/0.0.0.0:7447", "tcp/[::]:7447", "tcp/192.168.1.5:7447", "tls/fusion.example.com:7447",
          "tcp/10.0.0.1:7447?prio=1", "vsock/2:7447", "nonsense"]


def test_default_listens_on_loopback_only() -> None:
    assert zenoh_json(ZenohConfig()) == {
        "mode": "peer", "listen": {"endpoints": [DEFAULT_ENDPOINT]},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}, "delay": 0}}
    svc = load_service_config(ROOT / "configs" / "service.toml")
    assert all(is_local_endpoint(ep) for ep in svc.zenoh.listen)
    assert svc.zenoh.allow_remote is False and svc.zenoh.tls is None


@pytest.mark.parametrize("endpoint", LOCAL, ids=str)
def test_local_endpoints(endpoint: str) -> None:
    assert is_local_endpoint(endpoint)
    assert zenoh_json(ZenohConfig(listen=[endpoint]))["listen"] == {"endpoints": [endpoint]}


@pytest.mark.parametrize("endpoint", REMOTE, ids=str)
def test_remote_listen_endpoint_needs_allow_remote(endpoint: str) -> None:
    assert not is_local_endpoint(endpoint)
    with pytest.raises(ConfigError, match="allow_remote = true"):
        zenoh_json(ZenohConfig(listen=[DEFAULT_ENDPOINT, endpoint]))
    with pytest.raises(ConfigError, match="allow_remote"):
        session_config(mode="peer", listen=[endpoint])
    assert zenoh_json(ZenohConfig(listen=[endpoint], allow_remote=True))["listen"] == {"endpoints": [endpoint]}


def test_peer_and_client_need_endpoints() -> None:
    with pytest.raises(ConfigError, match="every interface"):
        zenoh_json(ZenohConfig(listen=[]))
    with pytest.raises(ConfigError, match="connect endpoint"):
        zenoh_json(ZenohConfig(mode="client", listen=[]))
    with pytest.raises(ConfigError, match="'peer' or 'client'"):
        session_config(mode="router", listen=[DEFAULT_ENDPOINT])
    # a client's listen list is ignored: it never listens
    assert "listen" not in zenoh_json(ZenohConfig(mode="client", connect=["tcp/192.0.2.1:7447"]))


def test_tls_json(certs: Certs) -> None:
    zc = ZenohConfig(listen=["tls/127.0.0.1:7447"], tls=certs.tls("fusion-service", require_client_certificate=True))
    assert zenoh_json(zc)["transport"] == {"link": {"protocols": ["tls"], "tls": {
        "root_ca_certificate": str(certs.ca),
        "listen_certificate": str(certs.cert("fusion-service")),
        "listen_private_key": str(certs.key("fusion-service")),
        "connect_certificate": str(certs.cert("fusion-service")),
        "connect_private_key": str(certs.key("fusion-service")),
        "enable_mtls": True}}}
    client = ZenohConfig(mode="client", connect=["tls/localhost:7447"], tls=certs.tls("viewer"))
    assert zenoh_json(client)["transport"]["link"]["tls"]["enable_mtls"] is True  # presents its certificate
    anonymous = ZenohConfig(mode="client", connect=["tls/localhost:7447"], tls=certs.tls(None))
    assert zenoh_json(anonymous)["transport"]["link"]["tls"] == {"root_ca_certificate": str(certs.ca),
                                                                "enable_mtls": False}


def test_tls_mistakes_are_refused(certs: Certs, tmp_path: Path) -> None:
    good = certs.tls("fusion-service", require_client_certificate=True)
    cases = [
        (ZenohConfig(listen=["tcp/127.0.0.1:7447"], tls=good), "every endpoint must be tls/"),
        (ZenohConfig(listen=["tls/127.0.0.1:7447"], connect=["tcp/127.0.0.1:7448"], tls=good), "every endpoint"),
        (ZenohConfig(listen=["tls/127.0.0.1:7447"], tls=certs.tls(None)), "needs its certificate and private_key"),
        (ZenohConfig(listen=["tls/127.0.0.1:7447"], tls=msgspec.structs.replace(good, private_key="")),
         "needs its certificate and private_key"),
        (ZenohConfig(mode="client", connect=["tls/127.0.0.1:7447"],
                     tls=msgspec.structs.replace(certs.tls("viewer"), private_key="")), "go together"),
        (ZenohConfig(listen=["tls/127.0.0.1:7447"], tls=msgspec.structs.replace(good, root_ca=str(tmp_path / "x"))),
         "root_ca: no file"),
        (ZenohConfig(mode="client", connect=["tls/127.0.0.1:7447"], tls=good), "for a listening peer"),
    ]
    for zc, match in cases:
        with pytest.raises(ConfigError, match=match):
            zenoh_json(zc)


def test_access_control_needs_client_certificates_on_a_listening_peer(certs: Certs) -> None:
    acl = AccessControlConfig(consumers=["viewer"])
    mtls = certs.tls("fusion-service", require_client_certificate=True)
    ep = ["tls/127.0.0.1:7447"]
    with pytest.raises(ConfigError, match="require_client_certificate = true"):
        zenoh_json(ZenohConfig(listen=["tcp/127.0.0.1:7447"], access_control=acl), namespace="demo")
    with pytest.raises(ConfigError, match="require_client_certificate = true"):
        zenoh_json(ZenohConfig(listen=ep, tls=certs.tls("fusion-service"), access_control=acl), namespace="demo")
    with pytest.raises(ConfigError, match="listening peer"):
        zenoh_json(ZenohConfig(mode="client", connect=ep, tls=certs.tls("viewer"), access_control=acl),
                   namespace="demo")
    with pytest.raises(ConfigError, match="namespace"):
        zenoh_json(ZenohConfig(listen=ep, tls=mtls, access_control=acl))
    conf = zenoh_json(ZenohConfig(listen=ep, tls=mtls, access_control=acl), namespace="demo")
    assert conf["access_control"]["default_permission"] == "deny"
    zenoh_session_config(ZenohConfig(listen=ep, tls=mtls, access_control=acl), namespace="demo")  # zenoh accepts it


def _grants(ac: AccessControlConfig) -> set[tuple[str, str, str, str]]:
    """(common name, message, flow, key) for every allow of the zenoh section."""
    sec = access_control_section(ac, namespace="ns")
    rules = {r["id"]: r for r in sec["rules"]}
    names = {s["id"]: s["cert_common_names"] for s in sec["subjects"]}
    out = set()
    for p in sec["policies"]:
        for rid in p["rules"]:
            r = rules[rid]
            assert r["permission"] == "allow" and len(r["messages"]) == len(r["flows"]) == 1
            for sid in p["subjects"]:
                out |= {(cn, r["messages"][0], r["flows"][0], k) for cn in names[sid] for k in r["key_exprs"]}
    return out


def test_access_control_profile() -> None:
    """What each identity may send to the service's peer (ingress) and receive from it (egress)."""
    ac = AccessControlConfig(sensors={"cam1": ["s-cam1"], "radar1": ["s-radar1", "s-radar1-spare"]},
                             inputs={"wheel": ["i-wheel"]}, simulators=["sim"], consumers=["view"], recorders=["rec"],
                             services=["svc"])
    g = _grants(ac)
    ingress = {(cn, msg, k) for cn, msg, flow, k in g if flow == "ingress"}
    egress = {(cn, msg, k) for cn, msg, flow, k in g if flow == "egress"}
    adv = {"s-cam1": ["fusion/ns/meas/cam1"], "s-radar1": ["fusion/ns/meas/radar1"],
           "s-radar1-spare": ["fusion/ns/meas/radar1"], "i-wheel": ["fusion/ns/input/wheel"],
           "sim": ["fusion/ns/meas/*", "fusion/ns/input/*"]}  # advanced publishers' keys
    subscribed = ["fusion/ns/meas/*", "fusion/ns/input/*"]  # the advanced subscribers' keys (rec, svc)
    samples = [*subscribed, "fusion/ns/truth/*"]
    assert {x for x in ingress if x[1] == "put"} == {
        ("s-cam1", "put", "fusion/ns/meas/cam1"), ("s-radar1", "put", "fusion/ns/meas/radar1"),
        ("s-radar1-spare", "put", "fusion/ns/meas/radar1"), ("i-wheel", "put", "fusion/ns/input/wheel"),
        *(("sim", "put", k) for k in samples), ("svc", "put", "fusion/ns/tracks/*"),
        *((cn, "put", f"{k}/@adv/pub/**") for cn, ks in adv.items() for k in ks)}  # heartbeats
    assert {x for x in ingress if x[1] in ("declare_queryable", "reply")} == {
        *(("svc", m, k) for m in ("declare_queryable", "reply") for k in ("fusion/ns/status", "fusion/ns/snapshot")),
        *((cn, "declare_queryable", f"{k}/@adv/pub/**") for cn, ks in adv.items() for k in ks),  # their caches
        *((cn, "reply", r) for cn, ks in adv.items() for k in ks for r in (k, f"{k}/@adv/pub/**"))}
    assert {x for x in ingress if x[1] == "query"} == {
        ("view", "query", "fusion/ns/status"), ("view", "query", "fusion/ns/snapshot"),
        # the advanced subscribers' history and recovery queries
        *((cn, "query", f"{k}/@adv/*/**") for cn in ("rec", "svc") for k in subscribed)}
    assert {x for x in ingress if x[1] == "declare_subscriber"} == {
        ("view", "declare_subscriber", "fusion/ns/tracks/*"),
        *((cn, "declare_subscriber", k) for cn in ("rec", "svc") for k in samples),
        *((cn, "declare_subscriber", f"{k}/@adv/pub/**") for cn in ("rec", "svc") for k in subscribed)}  # heartbeats
    assert {x for x in ingress if x[1].startswith("liveliness") or x[1] == "declare_liveliness_subscriber"} == {
        *((cn, "liveliness_token", f"{k}/@adv/pub/**") for cn, ks in adv.items() for k in ks),
        *((cn, "liveliness_query", f"{k}/@adv/sub/**") for cn, ks in adv.items() for k in ks),
        *((cn, m, f"{k}/@adv/pub/**") for cn in ("rec", "svc") for k in subscribed
          for m in ("declare_liveliness_subscriber", "liveliness_query")),
        *((cn, "liveliness_token", f"{k}/@adv/sub/**") for cn in ("rec", "svc") for k in subscribed)}
    assert {(cn, k) for cn, msg, k in egress if msg == "put"} == {
        ("view", "fusion/ns/tracks/*"), *((cn, k) for cn in ("rec", "svc") for k in samples),
        *((cn, f"{k}/@adv/pub/**") for cn in ("rec", "svc") for k in subscribed)}  # heartbeats
    # a control source's identity is a sensor's on its own key: nothing on measurements, truth or tracks
    assert {k for cn, _, _, k in g if cn == "i-wheel"} == {
        "fusion/ns/input/wheel", "fusion/ns/input/*", "fusion/ns/input/wheel/@adv/pub/**",
        "fusion/ns/input/*/@adv/*/**", "fusion/ns/input/*/@adv/pub/**", "fusion/ns/input/*/@adv/sub/**",
        "fusion/ns/input/wheel/@adv/sub/**"}
    assert access_control_section(AccessControlConfig(), namespace="ns") == {
        "enabled": True, "default_permission": "deny", "rules": [], "subjects": [], "policies": []}


@pytest.mark.parametrize("section, match", [
    ('[zenoh.access_control.sensors]\n"cam1\\n" = ["s"]', r"zenoh\.access_control\.sensors: a key: Expected str"),
    ('[zenoh.access_control.sensors]\n"a/b" = ["s"]', r"zenoh\.access_control\.sensors: a key: Expected str"),
    ('[zenoh.access_control.inputs]\n"*" = ["s"]', r"zenoh\.access_control\.inputs: a key: Expected str"),
    ('[zenoh.access_control]\nconsumers = [""]', r"zenoh\.access_control\.consumers\[0\]"),
    ('[zenoh.access_control]\nconsumers = [" viewer"]', r"zenoh\.access_control\.consumers\[0\]"),
    ('[zenoh.access_control]\nenabled = true', "unknown key 'enabled'"),
    ('[zenoh.tls]\nroot_ca = "ca.pem"\nverify = false', "unknown key 'verify'"),
    ('[zenoh.tls]\ncertificate = "c.pem"', "required key 'root_ca' is missing"),
], ids=["newline in sensor id", "slash in sensor id", "wildcard in source id", "empty name", "blank around name",
        "enabled", "unknown tls field", "tls without root_ca"])
def test_config_sections_refuse_mistakes(section: str, match: str) -> None:
    svc = (ROOT / "configs" / "service.toml").read_text()
    with pytest.raises(ConfigError, match=match):
        decode_service_config(svc + "\n" + section + "\n")


def test_grants_that_do_not_meet_the_tracker_are_said() -> None:
    """A grant for an id the tracker does not have is said (a typo leaves the real sensor without
    one: zenoh drops its samples unsaid), and so is a sensor nobody may put; a grant that meets
    the tracker says nothing. Not refused: a recorder may be meant to record a sensor the service
    does not fuse."""
    from publishers.spec import scenario_path

    svc = load_service_config(ROOT / "configs" / "service.toml")  # radar1 and cam1, no control source
    typo = AccessControlConfig(sensors={"radar1": ["r"], "cam2": ["c"]}, inputs={"control": ["i"]})
    assert mismatches(typo, svc.tracker) == [
        "zenoh.access_control.sensors grants 'cam2', which is not a sensor of [tracker] (its sensors: cam1, radar1): "
        "the service ignores its measurements",
        "zenoh.access_control.inputs grants 'control', which is not the tracker's control source (it has none): the "
        "service ignores its inputs",
        "sensor 'cam1' has no grant in zenoh.access_control.sensors and no simulators are named: nothing may put its "
        "measurements"]
    assert mismatches(msgspec.structs.replace(typo, simulators=["sim"]), svc.tracker)[2:] == []  # a simulator may
    assert mismatches(AccessControlConfig(sensors={"radar1": ["r"], "cam1": ["c"]}), svc.tracker) == []
    assert mismatches(None, svc.tracker) == []
    cv1d_d = decode_service_config(scenario_path("cv1d_d").read_text())  # sensor "pos", control source "control"
    assert mismatches(AccessControlConfig(sensors={"pos": ["p"]}, inputs={"wheel": ["w"]}), cv1d_d.tracker) == [
        "zenoh.access_control.inputs grants 'wheel', which is not the tracker's control source ('control'): the "
        "service ignores its inputs",
        "control source 'control' has no grant in zenoh.access_control.inputs and no simulators are named: nothing "
        "may put its inputs"]


def test_cli_zenoh_config(tmp_path: Path) -> None:
    assert cli_zenoh_config() == ZenohConfig(mode="client", listen=[], connect=[DEFAULT_ENDPOINT])
    assert cli_zenoh_config(connect=["tcp/127.0.0.1:1"]).connect == ["tcp/127.0.0.1:1"]
    peer = cli_zenoh_config(listen=["tcp/127.0.0.1:2"])
    assert (peer.mode, peer.listen, peer.connect) == ("peer", ["tcp/127.0.0.1:2"], [])
    f = tmp_path / "z.toml"
    f.write_text('[zenoh]\nmode = "client"\nconnect = ["tls/localhost:7447"]\n[zenoh.tls]\nroot_ca = "ca.pem"\n')
    zc = cli_zenoh_config(zenoh_file=f, connect=["tls/127.0.0.1:9"])
    assert zc.connect == ["tls/127.0.0.1:9"] and zc.tls == TlsConfig(root_ca="ca.pem")
    f.write_text('[zenoh]\nmode = "client"\nconect = ["tcp/127.0.0.1:1"]\n')
    with pytest.raises(ConfigError, match="unknown field `conect`"):
        load_zenoh_file(f)
    with pytest.raises(ConfigError, match="cannot read"):
        load_zenoh_file(tmp_path / "missing.toml")
