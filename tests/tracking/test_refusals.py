"""Intake: late data replays, bad data is refused with its reason, and the counts add up."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.config import TimeConfig
from fusion.tracking.detection import Detection, Reason
from fusion.tracking.results import Counts
from tests.tracking.helpers import Consumer, make_tracker
from tests.tracking.streams import NS_PER_S, Sensor, constant_velocity, detect, in_order

SEED = 4242
CART = Sensor("cart", "cartesian", period_s=0.5, std_m=1.0)
RADAR = Sensor("radar", "radar", period_s=0.5, offset_s=0.25, range_std_m=1.0, bearing_std_rad=0.002,
               position_m=(-500.0, 0.0))
TIME = TimeConfig(lag_s=2.0, future_s=10.0)
S = NS_PER_S


def tracker():
    return make_tracker([CART, RADAR], time=TIME)


def good_stream(seed: int = SEED) -> list[Detection]:
    rng = np.random.default_rng(seed)
    truth = constant_velocity(n_targets=2, duration_s=10.0, rng=rng, spread_m=200.0)
    return [d.det for d in in_order(detect(truth, CART, rng=rng), detect(truth, RADAR, rng=rng))]


def refused_total(counts: Counts) -> int:
    return sum(counts.refused.values())


def test_late_measurement_inside_the_window_replays_and_revises() -> None:
    dets = good_stream()
    late = next(d for d in dets if d.sensor_id == "radar" and d.t_ns == 5 * S + S // 4)
    first = [d for d in dets if d.t_ns <= 6 * S and d is not late]
    tr, consumer = tracker(), Consumer()
    for d in first:
        consumer.take(tr.process([d]))
    assert tr.counts.replays == 0
    result = tr.process([late])
    consumer.take(result)
    assert result.applied == 1 and not result.refused
    assert len(result.replays) == 1
    replay = result.replays[0]
    assert replay.trigger == (("radar", late.seq),)
    assert replay.from_t_ns == late.t_ns
    assert replay.n_scans == 4  # radar 5.25 (it held the other target's return), cart 5.5, radar 5.75, cart 6.0
    assert tr.counts.replays == 1 and tr.counts.late_applied == 1 and tr.counts.replayed_scans == 4
    revised = [e for e in result.estimates if e.revision > 0]
    assert revised, "the late radar return changes the later estimates: they come again with revision 1"
    assert {e.t_ns for e in revised} <= {5 * S + S // 2, 5 * S + 3 * S // 4, 6 * S}
    assert all(e.revision == 1 for e in revised)
    assert {e.revision for e in result.estimates if e.t_ns == late.t_ns} == {0}


def test_a_late_measurement_that_changes_nothing_emits_no_revision() -> None:
    """A late return from an unknown far-away point only starts a tentative track: the later
    estimates of the existing tracks are unchanged and are not emitted again."""
    dets = [d for d in good_stream() if d.t_ns <= 6 * S]
    tr, consumer = tracker(), Consumer()
    for d in dets:
        consumer.take(tr.process([d]))
    far = Detection.of("cart", 5 * S, 10_000, [5000.0, 5000.0])
    result = tr.process([far])
    consumer.take(result)
    assert len(result.replays) == 1
    assert all(e.track_id == result.each_association()[0].track_id for e in result.estimates if e.t_ns > 5 * S)
    assert not [e for e in result.estimates if e.revision > 0 and e.track_id != result.each_association()[0].track_id]


def refusal_of(tr, d: Detection) -> Reason | None:
    r = tr.process([d])
    assert len(r.refused) + r.applied == 1
    return r.refused[0].reason if r.refused else None


BAD = [
    ("unknown-sensor", Detection.of("lidar", 3 * S, 900, [0.0, 0.0]), Reason.UNKNOWN_SENSOR),
    ("nan", Detection.of("cart", 3 * S, 901, [np.nan, 0.0]), Reason.INVALID),
    ("inf", Detection.of("cart", 3 * S, 902, [0.0, np.inf]), Reason.INVALID),
    ("wrong-dimension-cart", Detection.of("cart", 3 * S, 903, [1.0, 2.0, 3.0]), Reason.INVALID),
    ("wrong-dimension-radar", Detection.of("radar", 3 * S, 904, [100.0]), Reason.INVALID),
    ("matrix-z", Detection.of("cart", 3 * S, 905, [[1.0, 2.0]]), Reason.INVALID),
    ("negative-range", Detection.of("radar", 3 * S, 906, [-5.0, 0.1]), Reason.INVALID),
    ("negative-seq", Detection.of("cart", 3 * S, -1, [0.0, 0.0]), Reason.INVALID),
    ("R-not-pd", Detection.of("cart", 3 * S, 907, [0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]]), Reason.BAD_COVARIANCE),
    ("R-asymmetric", Detection.of("cart", 3 * S, 908, [0.0, 0.0], [[1.0, 0.5], [0.0, 1.0]]), Reason.BAD_COVARIANCE),
    ("R-wrong-shape", Detection.of("cart", 3 * S, 909, [0.0, 0.0], np.eye(3)), Reason.BAD_COVARIANCE),
    ("R-nan", Detection.of("cart", 3 * S, 910, [0.0, 0.0], [[np.nan, 0.0], [0.0, 1.0]]), Reason.BAD_COVARIANCE),
    ("future", Detection.of("cart", 3 * S + 10 * S + 1, 911, [0.0, 0.0]), Reason.FUTURE),
    ("too-late", Detection.of("cart", 3 * S - 2 * S - 1, 912, [0.0, 0.0]), Reason.TOO_LATE),
    ("duplicate", Detection.of("cart", 3 * S, 6, [0.0, 0.0]), Reason.DUPLICATE),
    ("redelivered-after-window", Detection.of("cart", 0, 0, [0.0, 0.0]), Reason.TOO_LATE),
]


def primed():
    """A tracker whose clock reads 3 s: measurements every 0.5 s up to 3 s, and a second one at
    3 s (a source's clock believes a time once two of its measurements vouch for it:
    clock_outliers = 1). The radar has not spoken yet, so it does not hold the window back."""
    tr = tracker()
    tr.process([Detection.of("cart", k * S // 2, k, [0.0, 0.0]) for k in range(7)]
               + [Detection.of("cart", 3 * S, 7, [500.0, 0.0])])
    assert tr.now_ns == 3 * S and tr.horizon_ns == 1 * S
    return tr


@pytest.mark.parametrize(("d", "reason"), [(d, r) for _, d, r in BAD], ids=[i for i, _, _ in BAD])
def test_bad_measurement_is_refused_with_its_reason(d: Detection, reason: Reason) -> None:
    tr = primed()
    before = tr.counts
    assert refusal_of(tr, d) == reason
    assert tr.counts.refused[reason] == before.refused.get(reason, 0) + 1
    assert tr.counts.applied == before.applied


@pytest.mark.parametrize(
    ("d", "why"),
    [
        (Detection.of("cart", 3 * S + 10 * S, 950, [0.0, 0.0]), "exactly future_s ahead"),
        (Detection.of("cart", 3 * S - 2 * S + S // 2, 951, [0.0, 0.0]), "1.5 s late: inside the window"),
        (Detection.of("cart", 3 * S, 952, [1.0, 1.0], [[2.0, 0.5], [0.5, 1.0]]), "own positive definite R"),
        (Detection.of("radar", 2 * S, 0, [400.0, 0.2]), "seq 0 of another sensor"),
        (Detection.of("cart", 2 * S, 6, [1.0, 0.0]), "seq 6 again at another time: a restarted counter"),
    ],
    ids=["future-boundary", "late-in-window", "own-R", "same-seq-other-sensor", "same-seq-other-time"],
)
def test_edge_cases_that_are_accepted(d: Detection, why: str) -> None:
    tr = primed()
    assert refusal_of(tr, d) is None, why


def test_window_follows_the_clock_and_pruned_history() -> None:
    tr = primed()  # clock 3 s, lag 2 s: the window starts at 1 s
    assert refusal_of(tr, Detection.of("cart", 1 * S, 100, [0.0, 0.0])) is None  # exactly lag_s behind
    assert refusal_of(tr, Detection.of("cart", 6 * S, 101, [0.0, 0.0])) is None  # one witness of 6 s...
    assert tr.now_ns == 3 * S  # ...does not move the clock
    assert refusal_of(tr, Detection.of("cart", 6 * S, 102, [10.0, 0.0])) is None  # a second one does
    assert tr.now_ns == 6 * S and tr.horizon_ns == 4 * S
    assert refusal_of(tr, Detection.of("cart", 3 * S + S // 2, 103, [0.0, 0.0])) is Reason.TOO_LATE
    assert refusal_of(tr, Detection.of("cart", 4 * S - 1, 104, [0.0, 0.0])) is Reason.TOO_LATE
    assert refusal_of(tr, Detection.of("cart", 4 * S, 105, [0.0, 0.0])) is None  # exactly lag_s behind again
    # (cart, 100) left the window with its scan: it is now too late rather than a duplicate.
    assert refusal_of(tr, Detection.of("cart", 1 * S, 100, [0.0, 0.0])) is Reason.TOO_LATE
    assert refusal_of(tr, Detection.of("cart", 6 * S, 101, [0.0, 0.0])) is Reason.DUPLICATE
    c = tr.counts
    assert c.received == c.applied + refused_total(c) == 8 + 8
    assert (c.refused[Reason.TOO_LATE], c.refused[Reason.DUPLICATE]) == (3, 1)


def test_mixed_stream_counts_add_up_and_good_ones_are_applied() -> None:
    rng = np.random.default_rng(SEED)
    good = good_stream()
    start = [d for d in good if d.t_ns < 3 * S]
    rest = [d for d in good if d.t_ns >= 3 * S]
    tr = tracker()
    tr.process(start)
    # Bad measurements (at times inside the window so only their own fault refuses them) spliced in.
    bad: list[tuple[Detection, Reason]] = []
    for k, (_, d, reason) in enumerate(BAD):
        if reason in (Reason.FUTURE, Reason.TOO_LATE, Reason.DUPLICATE) or d.seq < 10:
            continue
        bad.append((Detection(d.sensor_id, 3 * S + k * S // 10, 10_000 + k if d.seq >= 0 else -1, d.z, d.R), reason))
    bad.append((Detection.of("cart", 100 * S, 20_000, [0.0, 0.0]), Reason.FUTURE))
    mixed: list[tuple[Detection, Reason | None]] = [(d, None) for d in rest] + bad
    order = rng.permutation(len(mixed))
    mixed = [mixed[i] for i in order]
    mixed.sort(key=lambda p: p[0].t_ns)  # the good ones in time order; the bad ones among them
    # A re-delivered good one (right after the original) and one from before the window.
    k = next(i for i, (d, r) in enumerate(mixed) if r is None and d.t_ns >= 6 * S)
    mixed.insert(k + 1, (mixed[k][0], Reason.DUPLICATE))
    mixed.insert(k + 2, (start[0], Reason.TOO_LATE))
    bad += [(mixed[k][0], Reason.DUPLICATE), (start[0], Reason.TOO_LATE)]
    outcome: list[Reason | None] = []  # per input, in delivery order: None = applied
    i = 0
    for n in rng.integers(1, 6, size=len(mixed)):
        batch = [d for d, _ in mixed[i : i + n]]
        if not batch:
            break
        i += n
        result = tr.process(batch)
        assert result.applied + len(result.refused) == len(batch)
        # Refusals come in input order: match them to the batch as a subsequence.
        pending = list(result.refused)
        for d in batch:
            if pending and (pending[0].sensor_id, pending[0].t_ns, pending[0].seq) == (d.sensor_id, d.t_ns, d.seq):
                outcome.append(pending.pop(0).reason)
            else:
                outcome.append(None)
        assert not pending
        accepted = {(d.sensor_id, d.seq) for d, o in zip(batch, outcome[-len(batch):], strict=True) if o is None}
        assert accepted <= {(a.sensor_id, a.seq) for a in result.each_association()}
    c = tr.counts
    assert c.received == len(start) + len(mixed)
    assert c.received == c.applied + refused_total(c)
    assert c.applied == len(good), "every good measurement is applied"
    assert refused_total(c) == len(bad)
    assert [o for o in outcome if o is not None] == [r for _, r in mixed if r is not None]
    assert outcome == [r for _, r in mixed], "each input exactly once: applied if good, refused with its reason if bad"


def test_a_reused_seq_never_gives_two_live_tracks_the_same_id() -> None:
    tr = tracker()
    for k in range(13):  # one target at rest, seen every 0.5 s for 6 s; its track started from (cart, 0)
        tr.process([Detection.of("cart", k * S // 2, k, [0.0, 0.0])])
    first = tr.tracks[0]
    assert first.origin == ("cart", 0) and first.status.label == "confirmed"
    result = tr.process([Detection.of("cart", 6 * S, 0, [3000.0, 3000.0])])  # the sensor restarted its seq
    ids = [t.id for t in tr.tracks]
    assert result.refused or len(ids) == len(set(ids)), f"live track ids {ids}"
