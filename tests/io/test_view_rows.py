"""fusion.io.view_rows.Fields: what the views read of the viewed estimates, read once, is each
estimate's own field, row for row, through take and concat."""

from __future__ import annotations

import numpy as np

from fusion.io.view_rows import Fields
from fusion.tracking.results import Estimate

_NAMES = ("prior_x", "meas_pos", "y", "S", "nis", "sensor_id", "H", "prior_P", "mode_probabilities")


def _estimates(n: int, seed: int) -> list[Estimate]:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        born = k % 4 == 0  # a birth: no prior, innovation or gain
        out.append(Estimate(k, 10 * k, "radar1" if k % 2 else "cam1", k, rng.normal(size=5), np.eye(5), "confirmed", 0,
                            None if born else float(rng.random()), None if born else rng.normal(size=2),
                            None if born else np.eye(2), None if k % 3 else rng.random(2),
                            None if born else rng.normal(size=2), None if born else rng.normal(size=5),
                            None if born else np.eye(5), None if born else rng.normal(size=(2, 5))))
    return out


def _same(f: Fields, es: list[Estimate]) -> None:
    for name in _NAMES:
        got = getattr(f, name)
        assert len(got) == len(es)
        for g, e in zip(got, es, strict=True):
            assert g is getattr(e, name)  # the estimate's own object, not a copy


def test_fields_of_take_concat() -> None:
    a, b = _estimates(9, 1), _estimates(5, 2)
    fa, fb = Fields.of(a), Fields.of(b)
    _same(fa, a)
    _same(fa.take([8, 0, 3]), [a[8], a[0], a[3]])
    _same(Fields.concat([fa, fb]), a + b)
    _same(Fields.of([]), [])
    _same(Fields.concat([fa, Fields.of([])]).take([]), [])
