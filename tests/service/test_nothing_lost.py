"""Nothing lost: publisher epochs, seq gaps, recovery from the publisher's cache, reconnection."""

from __future__ import annotations

import msgspec
import numpy as np
import pytest

from fusion import messages as m
from fusion.config import TimeConfig
from fusion.io import wire
from fusion.tracking.detection import Detection, Reason
from tests.tracking.test_refusals import CART, S
from tests.tracking.helpers import make_tracker

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
