"""Association: likelihood costs, and confirmed tracks before tentative ones (issue #9,
defects 4 and 6)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.config import InitConfig, TrackerConfig
from fusion.tracking.detection import Detection
from fusion.tracking.results import EventKind, Outcome
from fusion.tracking.tracker import Tracker
from fusion.tracking.trackset import track_id_for
from tests.tracking.helpers import Consumer, make_tracker
from tests.tracking.streams import NS_PER_S, Sensor, constant_velocity, detect, in_order, scans

S = NS_PER_S
CART = Sensor("cart", "cartesian", period_s=0.5, std_m=1.0)

RADARS = {  # (period, range std, bearing std): the target is ~1.5 km out
    "slow-fine": Sensor("radar", "radar", period_s=0.5, range_std_m=10.0, bearing_std_rad=0.001),
    "fast-coarse": Sensor("radar", "radar", period_s=0.1, range_std_m=5.0, bearing_std_rad=0.003),
    "slow-coarse": Sensor("radar", "radar", period_s=1.0, range_std_m=2.0, bearing_std_rad=0.002),
}


@pytest.mark.parametrize("component", [0, 1], ids=["range", "bearing"])
@pytest.mark.parametrize("seed", range(6), ids=[f"seed{k}" for k in range(6)])
@pytest.mark.parametrize("setup", sorted(RADARS))
def test_one_outlier_never_switches_a_lone_targets_id(setup: str, seed: int, component: int) -> None:
    """One target, one radar, no clutter, the default configuration (gate 0.999), and one +6
    sigma outlier at t = 10.5 s: one confirmed track from the start to the end, never deleted,
    and no second track confirmed."""
    radar = RADARS[setup]
    rng = np.random.default_rng(1000 + seed)
    truth = constant_velocity(n_targets=1, duration_s=25.0, rng=rng, spread_m=100.0)
    truth.x[:, 0, 0] += 1000.0
    truth.x[:, 0, 2] += 1000.0
    dets = in_order(detect(truth, radar, rng=rng))
    k = next(i for i, d in enumerate(dets) if d.det.t_ns >= round(10.5 * S))
    d = dets[k].det
    z = d.z.copy()
    z[component] += 6.0 * (radar.range_std_m, radar.bearing_std_rad)[component]
    outlier = Detection(d.sensor_id, d.t_ns, d.seq, z, d.R)
    tr = Tracker(TrackerConfig(sensors=[radar.config()]))
    confirmed, deleted = [], []
    for j, x in enumerate(dets):
        r = tr.process([outlier if j == k else x.det])
        confirmed += [e.track_id for e in r.events if e.kind == EventKind.CONFIRMED]
        deleted += [e.track_id for e in r.events if e.kind == EventKind.DELETED]
    assert len(confirmed) == 1, f"{setup} seed {seed}: confirmed {confirmed}"
    assert confirmed[0] not in deleted, f"{setup} seed {seed}: the target's track was deleted"
    assert [t.id for t in tr.confirmed()] == confirmed


def _confirmed_track_and_a_tentative_one(init: InitConfig | None = None) -> tuple[Tracker, int, int]:
    """A target at rest at the origin, confirmed over 6 scans; then a return 6 m away, outside
    the confirmed track's gate, starts a tentative track."""
    cfg = TrackerConfig(sensors=[CART.config()], **({"init": init} if init else {}))
    tr = Tracker(cfg)
    rng = np.random.default_rng(3)
    for k in range(6):
        tr.process([Detection.of("cart", k * S // 2, k, rng.normal(0.0, 0.3, 2))])
    (conf,) = tr.confirmed()
    r = tr.process([Detection.of("cart", 3 * S, 6, [0.0, 0.0]), Detection.of("cart", 3 * S, 7, [6.0, 0.0])])
    born = [e.track_id for e in r.events if e.kind == EventKind.BORN]
    assert born == [track_id_for("cart", 7, 3 * S)], r.each_association()
    return tr, conf.id, born[0]


def test_a_measurement_in_both_gates_updates_the_confirmed_track() -> None:
    """The tentative track's wide gate holds the next return too, with a smaller NIS; the
    likelihood (NIS + ln det S) and the precedence of confirmed tracks both give it to the
    confirmed track, which therefore does not miss the scan."""
    tr, conf, tent = _confirmed_track_and_a_tentative_one()
    r = tr.process([Detection.of("cart", 3 * S + S // 2, 8, [2.2, 0.0])])
    (a,) = r.each_association()
    assert set(a.gated) == {conf, tent}, a
    assert a.outcome == Outcome.UPDATED and a.track_id == conf


def test_confirmed_tracks_take_precedence_even_against_a_likelier_tentative_pair() -> None:
    """With a tight initiation prior the tentative track's gate is as narrow as the confirmed
    one's; a return nearer to the tentative track, in both gates, still goes to the confirmed
    track (Stone Soup's order: confirmed tracks first, leftovers to the initiator)."""
    tr, conf, tent = _confirmed_track_and_a_tentative_one(InitConfig(velocity_std_mps=0.5))
    r = tr.process([Detection.of("cart", 3 * S + S // 2, 8, [3.5, 0.0])])
    (a,) = r.each_association()
    assert set(a.gated) == {conf, tent}, a
    assert a.outcome == Outcome.UPDATED and a.track_id == conf


def test_leftovers_go_to_tentative_tracks() -> None:
    """Two returns: the confirmed track takes its own, the tentative track the other."""
    tr, conf, tent = _confirmed_track_and_a_tentative_one(InitConfig(velocity_std_mps=0.5))
    r = tr.process([Detection.of("cart", 3 * S + S // 2, 8, [0.1, 0.0]),
                    Detection.of("cart", 3 * S + S // 2, 9, [5.9, 0.0])])
    got = {a.seq: a.track_id for a in r.each_association()}
    assert got == {8: conf, 9: tent}


def test_crossing_in_clutter_confirmed_tracks_do_not_lose_scans_to_tentative_ones() -> None:
    """Over a cluttered crossing, a measurement that fell in a confirmed track's gate goes to a
    tentative track only when that confirmed track took another measurement of the scan."""
    rng = np.random.default_rng(21)
    truth = constant_velocity(n_targets=4, duration_s=30.0, rng=rng, crossing=True)
    dets = in_order(detect(truth, CART, rng=rng, pd=0.9, clutter_mean=8.0, region_m=(-300, 300, -300, 300)))
    tr = make_tracker([CART])
    consumer = Consumer()
    stolen = 0
    for batch in scans(dets):
        status = {t.id: t.status.label for t in tr.tracks}
        r = tr.process([d.det for d in batch])
        consumer.take(r)
        updated = {a.track_id for a in r.each_association() if a.outcome == Outcome.UPDATED}
        for a in r.each_association():
            if a.outcome == Outcome.UPDATED and status.get(a.track_id) == "tentative":
                stolen += any(status.get(g) == "confirmed" and g not in updated for g in a.gated)
    assert stolen == 0
    assert len(tr.confirmed()) >= 4
