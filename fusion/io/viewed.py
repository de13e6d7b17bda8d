"""Which tracks get views of their own in a recording: the first `limit` tracks by (sensor time
of their first confirmed estimate, track id), a function of the data whatever order it arrived in.

Taking the first tracks confirmed in arrival order would not be: a late measurement can confirm,
after the fact, a track earlier than one already shown, and two runs of the same data with
different delays would show different tracks. So a track is a *candidate* from its first
confirmed row on, and the choice waits for the data to be final:

    first(k)  = min t over the (t, sensor) rows of track k whose latest revision is confirmed
    order     = candidates sorted by (first(k), k)
    settle(h) : while fewer than `limit` are chosen and the head of `order` has first < h,
                choose it

where h is the tracker's horizon after the step (StepResult.horizon_ns): data before it are
refused, so no row before h can be revised and no other track can become confirmed before h;
the head's place is final. At the end of the data (close) every candidate is final. Once
`limit` are chosen the other candidates are dropped and no more are noted. What a candidate
costs until then: its rows' (t, sensor) -> (revision, confirmed), for the rows since its first
confirmed one, that is about the late window's worth.
"""

from __future__ import annotations

from fusion.io.labels import short_id
from fusion.tracking.results import Estimate

FINAL = 2**63 - 1  # a horizon past every time: the data are complete


class ViewedTracks:
    """The chosen tracks (`labels`: track id -> short label, in their order) and the candidates."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.labels: dict[int, str] = {}
        # candidate -> (t, sensor) -> (revision, confirmed) of its latest revision
        self._rows: dict[int, dict[tuple[int, str], tuple[int, bool]]] = {}

    @property
    def open(self) -> bool:
        """Whether tracks may still be chosen."""
        return len(self.labels) < self.limit

    def kept_ids(self) -> list[int]:
        """The tracks whose rows are kept: the chosen, then the candidates (until the choice is
        settled)."""
        return [*self.labels, *self._rows]

    def candidates(self) -> set[int]:
        return set(self._rows)

    def note(self, estimates: list[Estimate]) -> None:
        """Rows of a flush (retractions included), in the order they were made."""
        if not self.open:
            return
        rows = self._rows
        for e in estimates:
            k = e.track_id
            if k in self.labels:
                continue
            conf = e.status == "confirmed"
            got = rows.get(k)
            if got is None:
                if not conf:
                    continue
                got = rows[k] = {}
            key = (e.t_ns, e.sensor_id)
            old = got.get(key)
            if old is None or e.revision >= old[0]:
                got[key] = (e.revision, conf)

    def settle(self, horizon_ns: int | None) -> None:
        """Choose candidates in order while the head's first confirmed time is before the horizon;
        forget those with no confirmed row left; drop the rest once `limit` are chosen."""
        if horizon_ns is None or not self._rows:
            return
        first: dict[int, int] = {}
        for k, got in self._rows.items():
            times = [t for (t, _), (_, conf) in got.items() if conf]
            if times:
                first[k] = min(times)
        for k in [k for k in self._rows if k not in first]:
            del self._rows[k]
        for k in sorted(first, key=lambda k: (first[k], k)):
            if not self.open or first[k] >= horizon_ns:
                break
            self.labels[k] = short_id(k)
            del self._rows[k]
        if not self.open:
            self._rows.clear()

    def continue_from(self, other: ViewedTracks) -> None:
        self.labels = dict(other.labels)
        self._rows = {k: dict(v) for k, v in other._rows.items()}
