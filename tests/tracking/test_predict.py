"""Where is everything now: every confirmed track predicted to a requested time, with its
covariance; and the coasting event of a track that misses (issue #12, item 5)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.config import ModeConfig, MotionConfig
from fusion.core.gaussian import GaussianState
from fusion.core.kalman import ExtendedKalmanFilter
from fusion.tracking.detection import Detection
from fusion.tracking.results import EventKind
from tests.tracking.helpers import make_tracker
from tests.tracking.streams import NS_PER_S, Sensor

S = NS_PER_S
CART = Sensor("cart", "cartesian", period_s=0.5, std_m=1.0)
MOTIONS = {
    "cv": MotionConfig(model="cv", accel_psd_m2s3=0.5),
    "imm": MotionConfig(model="imm", modes=[ModeConfig(model="cv", accel_psd_m2s3=0.25, sojourn_s=20.0),
                                            ModeConfig(model="ct", accel_psd_m2s3=0.25, turn_psd_rad2s3=0.01,
                                                       sojourn_s=5.0)]),
}


def _tracker(name: str):
    tr = make_tracker([CART], motion=MOTIONS[name])
    for k in range(8):  # a target moving at 10 m/s along x
        tr.process([Detection.of("cart", k * S // 2, k, [5.0 * k, 0.0])])
    tr.process([Detection.of("cart", 4 * S, 100, [900.0, 900.0])])  # a tentative track elsewhere
    return tr


@pytest.mark.parametrize("name", sorted(MOTIONS))
def test_confirmed_tracks_predicted_to_a_requested_time(name: str) -> None:
    tr = _tracker(name)
    (conf,) = tr.confirmed()
    got = tr.predict(6 * S)
    assert [e.track_id for e in got] == [conf.id], "tentative tracks are not predicted"
    (e,) = got
    assert e.t_ns == 6 * S and e.status == "predicted" and e.sensor_id == "cart" and e.seq == 7
    assert abs(e.x[0] - 60.0) < 2.0  # 35 m at 3.5 s, then 2.5 s more at 10 m/s
    assert np.all(np.linalg.eigvalsh(e.P) > 0) and e.P[0, 0] > conf.state.P[0, 0]
    if name == "cv":  # exactly the filter's own prediction
        f = ExtendedKalmanFilter(tr.motion)
        ref = f.predict(GaussianState(conf.state.x, conf.state.P, conf.state.t_ns), 6 * S)
        np.testing.assert_allclose(e.x, ref.x, rtol=1e-12)
        np.testing.assert_allclose(e.P, ref.P, rtol=1e-12)
    else:
        assert e.mode_probabilities is not None and e.mode_probabilities.shape == (2,)


def test_a_track_updated_after_the_requested_time_is_not_predicted_backwards() -> None:
    tr = _tracker("cv")
    (e,) = tr.predict(2 * S)
    assert e.status == "confirmed" and e.t_ns == int(3.5 * S)


def test_a_confirmed_track_that_misses_starts_coasting_once() -> None:
    tr = make_tracker([CART])
    events = []
    for k in range(14):
        z = [5.0 * k, 0.0] if k < 8 or k >= 11 else [2000.0 + 100 * k, 2000.0]  # misses at k = 8, 9, 10
        events += tr.process([Detection.of("cart", k * S // 2, k, z)]).events
    (conf,) = [e.track_id for e in events if e.kind == EventKind.CONFIRMED]
    coasting = [e for e in events if e.kind == EventKind.COASTING and e.track_id == conf]
    assert [e.t_ns for e in coasting] == [4 * S]  # the first miss only
    assert conf in {t.id for t in tr.confirmed()}
