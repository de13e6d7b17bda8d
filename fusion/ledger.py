"""What a run of the service received and what became of each sample: the counts its status
reports (ServiceStatus.counts, fusion.messages) and its recording writes (`counts/*`).

They add up: received = applied + inputs + truth + duplicates + sum(refused) + queued, where
received is every sample the intake queue was offered; refused joins the refusals before decoding
(the queue's: size, rate, unknown key; and the samples shutdown dropped) with the pipeline's
(invalid, out of the window, ...; duplicates apart); queued = received less the refused at the
door, less the samples the loop has taken (`processed`), plus the measurements the pipeline holds
for a scan's rest (taken, not yet applied). The pipeline's counts are this run's: a tracker
resumed from a checkpoint carries its earlier counts, taken off here (`resumed`).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from typing import Any

from fusion.io.checkpointer import counts_since
from fusion.io.intake_queue import IntakeQueue, key_kind
from fusion.pipeline import Pipeline
from fusion.tracking.detection import Reason
from fusion.tracking.results import Counts


class Ledger:
    """The counts of one run of the service; the loop adds the samples it took (`took`) and those
    shutdown dropped (`dropped`)."""

    def __init__(self, pipeline: Pipeline, queue: IntakeQueue) -> None:
        self._pipeline = pipeline
        self._q = queue
        self._base = pipeline.counts()
        self._processed = 0  # samples the loop took from the queue
        self._dropped = 0  # samples still queued when shutdown's drain deadline came
        self._dropped_kinds: Counter[str] = Counter()  # of them, by their keys' kind (intake_queue.key_kind)

    def resumed(self) -> None:
        """A checkpoint was restored into the tracker: the counts it carried in are not this run's."""
        self._base = self._pipeline.counts()

    def took(self, n: int) -> None:
        """n samples taken from the queue by the loop."""
        self._processed += n

    def dropped(self, keys: Iterable[str]) -> None:
        """Samples dropped at shutdown (refused as "shutdown"), by their keys."""
        kinds = Counter(key_kind(k) for k in keys)
        self._dropped += kinds.total()
        self._dropped_kinds.update(kinds)

    @property
    def handled(self) -> int:
        """Samples taken by the loop or refused at the door."""
        return self._processed + self._q.refused_total

    def run_counts(self) -> Counts:
        """The pipeline's counts of this run (a resumed tracker's carried-in counts taken off)."""
        return counts_since(self._pipeline.counts(), self._base)

    def intake_refused(self) -> dict[str, int]:
        """Refusals before decoding, by reason: the intake queue's, and samples dropped at shutdown."""
        out = dict(self._q.refused)
        if self._dropped:
            out["shutdown"] = self._dropped
        return out

    def for_recording(self) -> dict[str, int]:
        """The flat counts the recording writes (`counts/<name>`)."""
        c = self.run_counts().flat()
        for reason, n in self.intake_refused().items():
            c[f"refused/{reason}"] = n
        return c

    def counts(self, *, published: int) -> dict[str, Any]:
        """The status's counts (see the module docstring); `published`: estimates published."""
        c = self.run_counts()
        refused = {r.value: n for r, n in c.refused.items() if r != Reason.DUPLICATE}
        intake = self.intake_refused()
        for reason, n in intake.items():
            refused[reason] = refused.get(reason, 0) + n
        arrived = self._q.offered
        queued = arrived - sum(intake.values()) - self._processed + self._pipeline.holding  # held: not yet applied
        kinds = self._q.refused_kinds + self._dropped_kinds  # refused before decoding, by their keys' kind
        return {
            "received": arrived, "applied": c.applied, "duplicates": c.duplicates,
            "refused": dict(sorted(refused.items())), "queued": queued, "replays": c.replays,
            "late_applied": c.late_applied, "published": published,
            "truth": c.truth, "inputs": c.inputs, "inputs_refused": c.inputs_refused + kinds["input"],
            "truth_refused": c.truth_refused + kinds["truth"], "other_refused": c.other_refused + kinds["other"],
        }
