"""Nothing lost: publisher epochs, seq gaps, recovery from the publisher's cache, reconnection."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

from fusion import messages as m
from fusion.cli.report import format_status
from fusion.cli.runner import Exit, explain_zenoh
from fusion.config import TimeConfig, ZenohConfig
from fusion.io import wire
from fusion.io.gaps import SensorGaps, SeqGaps
from fusion.io.query import query_status
from fusion.io.zenoh_advanced import declare_recoverable_publisher, wait_for_recovering_subscriber
from fusion.io.zenoh_bus import free_tcp_port, session_config, wait_for_match, zenoh_json
from fusion.service import Service
from fusion.tracking.detection import Detection, Reason
from tests.service.harness import client, running_service, scenario_config
from tests.tracking.helpers import make_tracker
from tests.tracking.test_refusals import CART, S

SEED = 1313
WIDE = TimeConfig(lag_s=10.0, future_s=10.0)  # every burst below stays inside the window


def _meas(seq: int, t_ns: int, *, epoch: int = 0, x: float = 0.0) -> m.Measurement:
    return m.Measurement(sensor_id="cart", t_ns=t_ns, seq=seq, epoch=epoch,
                         data=m.Cartesian(pos_m=[x, 0.0], std_m=[1.0, 1.0]))


# ---- 1. the publisher epoch ----------------------------------------------------------------------
def test_epoch_is_optional_on_the_wire_and_v_stays() -> None:
    plain = msgspec.msgpack.decode(m.encode(_meas(3, 5)))
    assert plain["v"] == 1 and "epoch" not in plain  # 0 is the default: left off
    with_epoch = msgspec.msgpack.decode(m.encode(_meas(3, 5, epoch=77)))
    assert with_epoch["v"] == 1 and with_epoch["epoch"] == 77
    old = msgspec.msgpack.encode({"type": "measurement", "v": 1, "sensor_id": "cart", "t_ns": 5, "seq": 3,
                                  "data": {"type": "cartesian", "pos_m": [1.0, 2.0]}})
    assert m.decode_measurement(old).epoch == 0  # a message from before epochs still decodes
    assert m.decode_measurement(m.encode(_meas(3, 5, epoch=77))).epoch == 77
    assert wire.Codec("t").detection(m.encode(_meas(3, 5, epoch=77))).epoch == 77
    with pytest.raises(m.InvalidMessageError, match=r"\$\.epoch"):
        m.decode_measurement(msgspec.msgpack.encode({**with_epoch, "epoch": -1}))


def _burst(epoch: int, rng: np.random.Generator, n: int = 6) -> list[Detection]:
    """A publisher's first n measurements after its start: seq from 0, every 0.5 s from 1 s."""
    return [Detection.of("cart", S + k * S // 2, k, [rng.normal(0, 1.0), 0.0], epoch=epoch) for k in range(n)]


def test_a_restarted_publisher_is_told_apart_from_a_replay() -> None:
    """The same sensor restarted (a new epoch) sends seq 0, 1, ... again at times it already
    sent them (a replayed scenario, a sensor that ticks on fixed times): inside the window, its
    measurements are new. The same epoch's messages again are duplicates."""
    rng = np.random.default_rng(SEED)
    tr = make_tracker([CART], time=WIDE)
    first, restarted = _burst(1_000, rng), _burst(2_000, rng)
    assert [(d.seq, d.t_ns) for d in first] == [(d.seq, d.t_ns) for d in restarted]
    assert not tr.process(first).refused
    r = tr.process(restarted)
    assert not r.refused, f"seed {SEED}: a restarted publisher was refused: {r.refused}"
    assert tr.counts.applied == 12
    replay = tr.process(first + restarted)
    assert [x.reason for x in replay.refused] == [Reason.DUPLICATE] * 12
    assert tr.counts.applied == 12


# ---- 2. seq gaps ---------------------------------------------------------------------------------
def test_gaps_count_missing_values_and_forget_filled_ones() -> None:
    g = SeqGaps()
    for s in (0, 1, 2, 5, 6, 9):
        g.add("a", 1, s)
    assert g.report()["a"] == SensorGaps(missing=4, filled=0, epochs=1, restarts=0)  # 3, 4, 7, 8
    for s in (4, 7, 7, 6):  # late arrivals fill two holes; a repeat changes nothing
        g.add("a", 1, s)
    assert g.report()["a"] == SensorGaps(missing=2, filled=2, epochs=1, restarts=0)
    g.add("a", 1, 12)  # a jump: 10, 11 missing
    g.add("a", 2, 0)  # the publisher restarted: a new run, its seq from 0 again is no gap
    g.add("a", 2, 2)
    assert g.report()["a"] == SensorGaps(missing=5, filled=2, epochs=2, restarts=1)
    g.add("b", 0, 10**12)  # a huge jump costs one interval, not 10**12 entries
    g.add("b", 0, 0)
    assert g.report()["b"].missing == 10**12 - 1


def test_gap_memory_is_bounded() -> None:
    rng = np.random.default_rng(SEED)
    g = SeqGaps(max_intervals=8, max_epochs=2)
    seqs = rng.permutation(1000)[:500]  # half of 0..999, in random order
    for s in seqs.tolist():
        g.add("a", 1, s)
    exact = int(seqs.max() - seqs.min() + 1 - len(seqs))
    assert g.report()["a"].missing >= exact  # given-up intervals stay counted, never lost
    for e in (2, 3, 4):
        g.add("a", e, 0)
    r = g.report()["a"]
    assert r.epochs == 4 and r.restarts == 3 and r.missing >= exact, f"seed {SEED}"


def test_gaps_are_reported_in_status_through_real_zenoh(tmp_path: Path) -> None:
    """A real zenoh client publishes cam1's seq 0..9 without 3, 4 and 7, then 7 late: status
    (the queryable, and `fusion status`'s text) says 2 missing, 1 filled."""
    _, cfg = scenario_config("mix")
    with running_service(cfg, tmp_path) as (svc, endpoint):
        session = client(endpoint)
        try:
            pub = session.declare_publisher(m.meas_key(cfg.namespace, "cam1"))
            assert wait_for_match(pub, timeout_s=5.0)
            for seq in (0, 1, 2, 5, 6, 8, 9, 7):
                pub.put(m.encode(m.Measurement(sensor_id="cam1", t_ns=seq * S // 5, seq=seq, epoch=42,
                                               data=m.Cartesian(pos_m=[100.0 + seq, 0.0]))))
            assert svc.wait_idle(timeout_s=30.0)
            st = query_status(session, cfg.namespace, timeout_s=5.0)
        finally:
            session.close()
    assert st.counts.applied == 8
    assert st.gaps["cam1"] == m.SeqGapStats(missing=2, filled=1, epochs=1, restarts=0)
    assert "seq gaps   cam1: 2 missing, 1 filled late" in format_status(st, cfg.namespace)


# ---- 3. zenoh's advanced publisher and subscriber -------------------------------------------------
def _cam1(seq: int, *, pad: bool = False) -> bytes:
    """cam1's measurement seq at seq/5 s; pad=True carries its own covariance (a larger payload)."""
    cov = [1.0, 0.0, 0.0, 1.0] if pad else None
    return m.encode(m.Measurement(sensor_id="cam1", t_ns=seq * S // 5, seq=seq, epoch=7,
                                  data=m.Cartesian(pos_m=[100.0 + seq, 0.0], cov_m2=cov)))


def _lossy_client(endpoint: str, ns: str, *, size_limit: int) -> Any:
    """A client whose measurement puts larger than size_limit bytes are dropped as they leave
    (zenoh's low-pass filter, egress): a sample lost on the way, deterministically. Replies from
    the advanced publisher's cache are not puts and pass."""
    import zenoh

    conf = zenoh_json(ZenohConfig(mode="client", listen=[], connect=[endpoint]))
    conf["low_pass_filter"] = [{"flows": ["egress"], "messages": ["put"], "key_exprs": [f"fusion/{ns}/meas/**"],
                                "size_limit": size_limit}]
    return zenoh.open(zenoh.Config.from_json5(json.dumps(conf)))


def test_a_service_that_joins_late_recovers_from_the_publishers_cache(tmp_path: Path) -> None:
    """The publisher puts 20 measurements with no service anywhere; the service then starts and
    its subscription fetches all 20 from the publisher's cache."""
    _, cfg = scenario_config("mix")
    port = free_tcp_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    import zenoh

    hub = zenoh.open(session_config(mode="peer", listen=[endpoint]))  # the sensors' router
    try:
        pub_session = client(endpoint)
        try:
            pub = declare_recoverable_publisher(pub_session, m.meas_key(cfg.namespace, "cam1"), cache_samples=100)
            for seq in range(20):
                pub.put(_cam1(seq))
            svc_cfg = msgspec.structs.replace(cfg, zenoh=ZenohConfig(mode="client", listen=[], connect=[endpoint]))
            svc = Service(svc_cfg, recording_path=tmp_path / "late.rrd", stream_path=tmp_path / "late.fstream")
            t = threading.Thread(target=svc.run, name="late-service")
            svc.open()
            t.start()
            try:
                deadline = time.monotonic() + 10.0
                while svc.status_dict()["counts"]["applied"] < 20 and time.monotonic() < deadline:
                    time.sleep(0.02)
                assert svc.wait_idle(timeout_s=30.0)
                st = svc.status_dict()
            finally:
                svc.stop()
                t.join(timeout=60)
            pub.undeclare()
        finally:
            pub_session.close()
    finally:
        hub.close()
    assert st["counts"]["received"] == 20 and st["counts"]["applied"] == 20, st["counts"]
    assert st["gaps"]["cam1"]["missing"] == 0


@pytest.mark.parametrize(("cache", "recovered"), [(100, True), (1, False)], ids=["recovered", "cache-too-small"])
def test_a_sample_dropped_on_the_way_is_recovered_or_counted(tmp_path: Path, cache: int, recovered: bool) -> None:
    """seq 3 and 4 are dropped as they leave the publisher. With a cache that still holds them
    the service recovers both (nothing missing); with a cache of 1 it cannot, and status says
    zenoh reported 2 missed and the seq gap is 2."""
    _, cfg = scenario_config("mix")
    small = max(len(_cam1(seq)) for seq in range(10))
    assert min(len(_cam1(seq, pad=True)) for seq in (3, 4)) > small
    with running_service(cfg, tmp_path) as (svc, endpoint):
        session = _lossy_client(endpoint, cfg.namespace, size_limit=small)
        try:
            pub = declare_recoverable_publisher(session, m.meas_key(cfg.namespace, "cam1"), cache_samples=cache,
                                                heartbeat_s=0.1)
            assert wait_for_recovering_subscriber(session, m.meas_key(cfg.namespace, "cam1"), timeout_s=5.0)
            time.sleep(0.3)  # the publisher's cache queryable must reach the service before a loss
            for seq in range(10):
                pub.put(_cam1(seq, pad=seq in (3, 4)))
            deadline = time.monotonic() + 10.0
            want = 10 if recovered else 8
            while svc.status_dict()["counts"]["applied"] < want and time.monotonic() < deadline:
                time.sleep(0.02)
            time.sleep(0.5)  # a few heartbeats: nothing more arrives
            assert svc.wait_idle(timeout_s=30.0)
            st = svc.status_dict()
            pub.undeclare()
        finally:
            session.close()
    assert st["counts"]["applied"] == want, (st["counts"], st["gaps"])  # the gaps say whether zenoh reported a miss
    g = st["gaps"]["cam1"]
    if recovered:
        assert g["missing"] == 0 and g.get("zenoh_missed", 0) == 0, g
    else:
        assert g["missing"] == 2 and g["zenoh_missed"] == 2, g


# ---- 4. a client service whose peer is not there yet, or goes away --------------------------------
def _wait(cond: Any, timeout_s: float = 15.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def _put_cam1(endpoint: str, ns: str, seqs: range) -> None:
    session = client(endpoint)
    try:
        pub = declare_recoverable_publisher(session, m.meas_key(ns, "cam1"))
        assert wait_for_recovering_subscriber(session, m.meas_key(ns, "cam1"), timeout_s=10.0)
        for seq in seqs:
            pub.put(_cam1(seq))
        time.sleep(0.3)
        pub.undeclare()
    finally:
        session.close()


def test_a_client_service_waits_for_its_peer_and_reconnects(tmp_path: Path) -> None:
    import zenoh

    _, cfg = scenario_config("mix")
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    zc = ZenohConfig(mode="client", listen=[], connect=[endpoint], connect_wait_s=20.0, retry_max_s=0.2)
    svc = Service(msgspec.structs.replace(cfg, zenoh=zc), recording_path=tmp_path / "c.rrd",
                  stream_path=tmp_path / "c.fstream")
    t = threading.Thread(target=svc.run, name="client-service")  # run() opens: retrying until the peer is up
    t.start()
    hub = None
    try:
        time.sleep(0.8)
        assert svc.session is None and t.is_alive(), "the service gave up or connected to nothing"
        hub = zenoh.open(session_config(mode="peer", listen=[endpoint]))
        assert _wait(lambda: svc.session is not None)
        assert svc.status_dict()["zenoh"]["connect_attempts"] > 1
        _put_cam1(endpoint, cfg.namespace, range(0, 3))
        assert _wait(lambda: svc.status_dict()["counts"]["applied"] == 3)
        assert svc.status_dict()["zenoh"]["state"] == "connected"
        hub.close()  # the peer goes away ...
        hub = None
        assert _wait(lambda: svc.status_dict()["zenoh"]["state"] == "disconnected")
        hub = zenoh.open(session_config(mode="peer", listen=[endpoint]))  # ... and comes back
        assert _wait(lambda: svc.status_dict()["zenoh"]["state"] == "connected")
        _put_cam1(endpoint, cfg.namespace, range(3, 6))
        assert _wait(lambda: svc.status_dict()["counts"]["applied"] == 6)
        link = svc.status_dict()["zenoh"]
        assert link["reconnects"] == 1 and link["mode"] == "client", link
        assert "zenoh      client connected" in format_status(m.decode_status(wire.encode_status(svc.status_dict())),
                                                            cfg.namespace)
    finally:
        svc.stop()
        t.join(timeout=60)
        if hub is not None:
            hub.close()
    assert not t.is_alive()


def test_a_client_service_with_no_peer_gives_up_after_connect_wait(tmp_path: Path) -> None:
    _, cfg = scenario_config("mix")
    zc = ZenohConfig(mode="client", listen=[], connect=[f"tcp/127.0.0.1:{free_tcp_port()}"], connect_wait_s=0.5,
                     retry_max_s=0.1)
    svc = Service(msgspec.structs.replace(cfg, zenoh=zc), recording_path=tmp_path / "n.rrd")
    t0 = time.monotonic()
    with pytest.raises(Exception, match="Unable to connect") as e:
        svc.open()
    assert 0.5 <= time.monotonic() - t0 < 5.0
    assert not (tmp_path / "n.rrd").exists(), "a service that could not start left a recording"
    err = explain_zenoh(e.value, where="fusion serve")
    assert err.code == Exit.CONNECT and "start the peer or router" in str(err) and "fusion serve" not in str(err)


def test_a_service_stopped_while_connecting_stops_at_once(tmp_path: Path) -> None:
    _, cfg = scenario_config("mix")
    zc = ZenohConfig(mode="client", listen=[], connect=[f"tcp/127.0.0.1:{free_tcp_port()}"], connect_wait_s=60.0)
    svc = Service(msgspec.structs.replace(cfg, zenoh=zc), recording_path=tmp_path / "s.rrd")
    t = threading.Thread(target=svc.run, name="stopped-while-connecting")
    t.start()
    time.sleep(0.5)
    t0 = time.monotonic()
    svc.stop()
    t.join(timeout=10)
    assert not t.is_alive() and time.monotonic() - t0 < 3.0
    assert svc.session is None and not (tmp_path / "s.rrd").exists()
