"""Late data end to end: the service as shipped (`fusion serve --config configs/service.toml`,
recording on), blasted with the same measurements in time order and with 10 % of them late.

The load is bench.service_e2e's (bench.e2e_load: T targets, radar1 10 Hz + cam1 5 Hz, congestion
control BLOCK), prepared twice from the same scene: in time order, and with each measurement
after the first 30 scans held back with probability 0.1 and sent after the scan 1 to 25 scans
after its own (bench.e2e_load.Prepared's `late`; 25 scans are 1.7 s: inside the 2 s window), as
bench.late_data holds them back. Throughput is bench.service_e2e.throughput_run's (measurements
applied per second over a window after the warm-up, from the service's status); the two orders
alternate in each repeat, so each pair shares the machine's load. Reported per target count:
applied/s in order and late (median [min-max]), their ratio per pair (in order / late: the cost
of the late data; issue #11 goal 5 asks <= 2x), and what the late runs counted: measurements
applied late, replays, refusals (a late measurement refused would mean it left the window).

Latency at 10k measurements/s offered (667 targets; bench.service_e2e.latency_run: scans as
bursts at their due times, the late measurements at the end of a later scan's burst), in order
and 10 % late, alternating: whether the service kept up, and the p50 of publish-to-estimate
latency (arrival of an estimate's first revision - its t_ns). The p99 is not shown: with 10 % of
the measurements sent 67 ms to 1.7 s after their time, it is their lateness, not the service's.

The throughput is the figure of a saturated service: it drains up to intake.batch_max (5 000) samples per
tracker call, and a full batch holding late data up to intake.late_batch_max (20 000), so a late
measurement and the scans after it are often run in one call, and one rewind covers all the
late data of a batch. bench.late_data gives the tracker's figure with one
call per scan (a service keeping up with each scan as it comes), where every late measurement
costs a replay of its own.
"""

from __future__ import annotations

import statistics
import tempfile
from pathlib import Path
from typing import Any

from bench.e2e_procs import Publisher
from bench.service_e2e import latency_run, throughput_run

LATE = 0.1


def _spread(xs: list[float], fmt: str = ",.0f") -> str:
    return f"{statistics.median(xs):{fmt}} [{min(xs):{fmt}}-{max(xs):{fmt}}]"


def run(*, quick: bool = False, sizes: tuple[int, ...] = (100, 1000)) -> dict[str, Any]:
    repeats = 1 if quick else 3
    n = 60_000 if quick else 150_000
    window_s, warm_dl, after_warm_s = (4.0, 40.0, 30.0) if quick else (5.0, 60.0, 40.0)
    print(f"late data end to end: fusion serve --config configs/service.toml, recording on; {n} measurements, "
          f"in time order and {LATE:.0%} late (1-25 scans), alternating, {repeats} repeats", flush=True)
    out: dict[str, Any] = {"runs": []}
    with tempfile.TemporaryDirectory(prefix="fusion-late-e2e-") as d, Publisher() as pub:
        tmp = Path(d)
        for targets in sizes:
            rates: dict[float, list[float]] = {0.0: [], LATE: []}
            ratios: list[float] = []
            late_runs: list[dict[str, Any]] = []
            for rep in range(repeats):
                pair: dict[float, float] = {}
                for late in (0.0, LATE):
                    pub.call("prepare", {"targets": targets, "messages": n, "seed": targets, "late": late},
                             timeout_s=300.0)
                    r = throughput_run(pub, tmp / f"late-{targets}-{late}-{rep}", n=n, targets=targets, recording=True,
                                       window_s=window_s, warm_deadline_s=warm_dl, after_warm_s=after_warm_s)
                    r |= {"late_fraction": late}
                    out["runs"].append(r)
                    if r["rate"] is not None:
                        rates[late].append(r["rate"])
                        pair[late] = r["rate"]
                    if late:
                        late_runs.append(r)
                    print(f"  T={targets} {'late' if late else 'in order'}: "
                          f"{'n/a' if r['rate'] is None else format(r['rate'], ',.0f')}/s, applied late "
                          f"{r['late_applied']:,}, replays {r['replays']:,}, refused {r['refused'] or 'none'}, "
                          f"{'drained' if r['drained'] else 'not drained'}", flush=True)
                if len(pair) == 2:
                    ratios.append(pair[0.0] / pair[LATE])
            if rates[0.0] and rates[LATE] and ratios:
                print(f"T={targets}: in order {_spread(rates[0.0])}/s, {LATE:.0%} late {_spread(rates[LATE])}/s: "
                      f"in order / late {_spread(ratios, '.2f')}x (goal <= 2x); per pair "
                      f"{', '.join(f'{x:.2f}' for x in ratios)}", flush=True)
                out[f"late_e2e_{targets}_ratio"] = statistics.median(ratios)
                out[f"late_e2e_{targets}_in_order_rate"] = statistics.median(rates[0.0])
                out[f"late_e2e_{targets}_late_rate"] = statistics.median(rates[LATE])
                out[f"late_e2e_{targets}_refused"] = sum(sum(r["refused"].values()) for r in late_runs)
    dur, grace = (4.0, 2.0) if quick else (20.0, 3.0)
    with tempfile.TemporaryDirectory(prefix="fusion-late-lat-") as d, Publisher() as pub:
        p50: dict[float, list[float]] = {0.0: [], LATE: []}
        for rep in range(repeats):
            for late in (0.0, LATE):
                r = latency_run(pub, Path(d) / f"lat-{late}-{rep}", rate=10_000, recording=True, duration_s=dur,
                                grace_s=grace, late=late)
                out["runs"].append(r | {"late_fraction": late})
                if r["p50_ms"] is not None:
                    p50[late].append(r["p50_ms"])
                print(f"  10k/s {'late' if late else 'in order'}: p50 "
                      f"{'n/a' if r['p50_ms'] is None else format(r['p50_ms'], '.1f')} ms, "
                      f"{'kept up' if r['kept_up'] else 'fell behind: ' + format(r['unhandled_end'], ',')}, "
                      f"refused {r['refused'] or 'none'}", flush=True)
        if p50[0.0] and p50[LATE]:
            print(f"10k/s offered: p50 in order {_spread(p50[0.0], '.1f')} ms, {LATE:.0%} late "
                  f"{_spread(p50[LATE], '.1f')} ms", flush=True)
            out["late_e2e_10k_p50_ms_in_order"] = statistics.median(p50[0.0])
            out["late_e2e_10k_p50_ms_late"] = statistics.median(p50[LATE])
    return out


if __name__ == "__main__":
    import sys

    run(quick="--quick" in sys.argv, sizes=tuple(int(a) for a in sys.argv[1:] if a.isdigit()) or (100, 1000))
