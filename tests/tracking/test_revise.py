"""history.revise (the revisions of a scan run again, kept as columns: history.Emitted) against
the dict of (revision, signature, alive) per track it replaced, kept here as the reference: runs
of one scan again and again with tracks produced unchanged, changed, newly, not at all, kept
by a partial re-run, and produced again after a retraction."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.tracking.history import Entry, revise, signatures_of
from fusion.tracking.results import Estimate

KEY = (5_000, "radar1")


def _reference(emitted: dict, old: dict, new: list[Estimate], kept: set[int]) -> list[Estimate]:
    emitted.update(old)
    out: list[Estimate] = []
    produced: set[int] = set()
    for e in new:
        sig = int(signatures_of([e])[0])
        produced.add(e.track_id)
        o = old.get(e.track_id)
        if o is not None and o[2] and o[1] == sig:
            emitted[e.track_id] = o
            continue
        rev = 0 if o is None else o[0] + 1
        emitted[e.track_id] = (rev, sig, True)
        out.append(e.with_revision(rev))
    gone = old.keys() - produced
    stand = gone & kept if kept else set()
    for tid in sorted(gone - stand):
        rev, sig, alive = old[tid]
        if alive:
            rev += 1
            out.append(Estimate.retraction((tid, KEY[0], KEY[1]), rev))
        emitted[tid] = (rev, sig, False)
    return out


def _estimate(tid: int, value: float) -> Estimate:
    return Estimate(tid, KEY[0], KEY[1], tid % 97, np.array([value, 1.0]), np.eye(2) * value, "confirmed", 0, 0.5)


def _same(a: list[Estimate], b: list[Estimate]) -> bool:
    return [(e.track_id, e.revision, e.status, e.x.tobytes()) for e in a] == \
        [(e.track_id, e.revision, e.status, e.x.tobytes()) for e in b]


@pytest.mark.parametrize("seed", range(10))
def test_revise_equals_the_dict_of_revisions(seed: int) -> None:
    rng = np.random.default_rng(seed)
    ids = rng.choice(2**62, size=30, replace=False)  # track ids: 63-bit hashes
    value = {int(t): 1.0 for t in ids}
    prev, ref = None, {}
    for _ in range(25):  # the same scan, run again and again
        chosen = sorted(int(t) for t in ids[rng.random(len(ids)) < 0.7])
        for t in chosen:
            if rng.random() < 0.3:
                value[t] += 1.0  # changed: a new revision
        new = [_estimate(t, value[t]) for t in chosen]
        if rng.random() < 0.5:
            new = [new[i] for i in rng.permutation(len(new))]  # the order given is kept
        kept = {int(t) for t in ids[rng.random(len(ids)) < 0.2]} if rng.random() < 0.5 else set()
        entry = Entry(KEY, (), None)  # type: ignore[arg-type]
        got = revise(entry, prev, new, np.array(sorted(kept), dtype=np.int64))
        ref_new: dict = {}
        want = _reference(ref_new, ref, new, kept)
        assert _same(got, want)
        assert len(entry.emitted) == len(ref_new)
        for t, r in ref_new.items():
            assert t in entry.emitted and entry.emitted[t] == r
        assert np.all(np.diff(entry.emitted.table[0]) > 0)
        prev, ref = entry, ref_new


def test_first_run_reports_everything_at_revision_zero() -> None:
    entry = Entry(KEY, (), None)  # type: ignore[arg-type]
    out = revise(entry, None, [_estimate(3, 1.0), _estimate(1, 2.0)])
    assert [(e.track_id, e.revision) for e in out] == [(3, 0), (1, 0)]
    assert entry.emitted.table[0].tolist() == [1, 3] and 2 not in entry.emitted
    with pytest.raises(KeyError):
        entry.emitted[2]


def test_a_signature_changes_with_any_word_of_x_p_or_the_status() -> None:
    """signatures_of: the same bits, the same signature; one ulp in any component of x or P, the
    sign of a zero, or the status, another (mix is a bijection: one word never collides)."""
    rng = np.random.default_rng(3)
    base = Estimate(7, KEY[0], KEY[1], 1, rng.normal(size=4), rng.normal(size=(4, 4)), "confirmed", 0, 0.5)
    sig = int(signatures_of([base])[0])
    copy = Estimate(7, KEY[0], KEY[1], 1, base.x.copy(), base.P.copy(), "confirmed", 3, 9.0)  # revision, nis: unsigned
    assert int(signatures_of([copy])[0]) == sig
    seen = {sig}
    for field, shape in (("x", (4,)), ("P", (4, 4))):
        for idx in np.ndindex(*shape):
            x, P = base.x.copy(), base.P.copy()
            a = x if field == "x" else P
            a[idx] = np.nextafter(a[idx], np.inf)
            seen.add(int(signatures_of([Estimate(7, KEY[0], KEY[1], 1, x, P, "confirmed", 0, 0.5)])[0]))
    assert len(seen) == 1 + 4 + 16
    tentative = Estimate(7, KEY[0], KEY[1], 1, base.x, base.P, "tentative", 0, 0.5)
    assert int(signatures_of([tentative])[0]) != sig
    zero = np.zeros(4)
    assert signatures_of([Estimate(1, 0, "s", 0, zero, np.eye(4), "confirmed", 0, None)])[0] != \
        signatures_of([Estimate(1, 0, "s", 0, -zero, np.eye(4), "confirmed", 0, None)])[0]
    nan = np.full(4, np.nan)
    assert signatures_of([Estimate(1, 0, "s", 0, nan, np.eye(4), "confirmed", 0, None)])[0] == \
        signatures_of([Estimate(1, 0, "s", 0, nan.copy(), np.eye(4), "confirmed", 0, None)])[0]


def test_a_scan_s_signatures_are_those_of_its_estimates() -> None:
    """run_scan signs its estimates from its blocks (revision_kernel.row_signatures), in the order of the
    estimates it returns (births among them, sorted by id): the same as signing the estimates."""
    from bench.late_data import scans, shipped_config
    from fusion.tracking.scan import run_scan
    from fusion.tracking.tracker import Tracker

    data = scans(30, 3.0)
    tr = Tracker(shipped_config())
    checked = 0
    for s in data:
        ts = tr.track_set
        key = (s[0].t_ns, s[0].sensor_id)
        tr.process(s)
        entry = tr.history.entries[-1]
        if entry.key != key:
            continue
        out = run_scan(ts, key, entry.dets, tr.ctx)
        assert out.signatures is not None and len(out.signatures) == len(out.estimates)
        assert out.signatures.tolist() == signatures_of(out.estimates).tolist()
        checked += len(out.estimates)
    assert checked > 500
