"""Tables of the end-to-end benchmark (bench.service_e2e): medians with min-max spreads."""

from __future__ import annotations

import statistics
from typing import Any


def spread(xs: list[Any], fmt: str = ",.0f") -> str:
    """'median (min-max)' of the values that are numbers; 'n/a' when there are none."""
    v = [x for x in xs if isinstance(x, (int, float)) and x == x]
    if not v:
        return "n/a"
    if len(v) == 1:
        return format(v[0], fmt)
    return f"{format(statistics.median(v), fmt)} ({format(min(v), fmt)}-{format(max(v), fmt)})"


def throughput_line(r: dict[str, Any]) -> str:
    rate = "n/a" if r["rate"] is None else f"{r['rate']:,.0f}/s"
    end = (f"drained {r['drain_s']:.1f} s after the last put" if r["drained"]
           else f"{r['unhandled_end']:,} not handled yet{'' if r['warm'] else ', window before the warm-up ended'}")
    rec = "on" if r["recording"] else "off"
    scene = " dense" if r.get("scene") == "dense" else ""
    return (f"service T={r['targets']}{scene} recording {rec}: {rate} over {r['window_s']:.1f} s, {end} "
            f"(primer {r['prime_s']:.1f} s, {r['status_updates']} status updates)")


def latency_line(r: dict[str, Any]) -> str:
    return (f"latency {r['rate']}/s T={r['targets']} recording {'on' if r['recording'] else 'off'}: "
            f"p50 {_ms(r, 'p50_ms')}, p99 {_ms(r, 'p99_ms')}, max {_ms(r, 'max_ms')} ms, coverage {r['coverage']:.2f}"
            f"{'' if r['kept_up'] else ', fell behind: ' + format(r['unhandled_end'], ',') + ' not handled'}")


def _ms(r: dict[str, Any], key: str) -> str:
    v = r[key]
    return f"> {r['waited_after_publishing_s'] * 1e3:,.0f}" if v is None else f"{v:,.1f}"


def lat_cell(rs: list[dict[str, Any]], key: str) -> str:
    """spread of a latency percentile; runs where it is censored show as '> waited' instead."""
    known = spread([r[key] for r in rs], ",.1f")
    cens = [r["waited_after_publishing_s"] * 1e3 for r in rs if r[key] is None]
    if not cens:
        return known
    c = f">{min(cens):,.0f} ({len(cens)}/{len(rs)})"
    return c if known == "n/a" else f"{known}; {c}"


def print_throughput(out: dict[str, Any], *, repeats: int, n: int) -> None:
    print(f"\nend to end, throughput: {n} measurements blasted (BLOCK), median (min-max) of {repeats}; "
          "rate = applied/s from the service's status over the steady window")
    print(f"{'scene':>5} {'targets':>7} {'recording':>9} {'service /s':>22} {'zenoh /s':>26} {'ratio':>8} "
          f"{'drain s':>14} {'kB/meas':>8}  notes")
    runs = out["throughput"]
    for scene, targets, rec in sorted({(r.get("scene", "grid"), r["targets"], r["recording"]) for r in runs},
                                      key=lambda k: (k[0] != "grid", k[1], not k[2])):
        base = [b["rate"] for b in out["baseline"] if b["targets"] == targets and b.get("scene", "grid") == scene]
        rs = [r for r in runs if r["targets"] == targets and r["recording"] == rec and r.get("scene", "grid") == scene]
        ratio = [r["rate"] / r["baseline_rate"] for r in rs]
        drain = [r["drain_s"] for r in rs]
        notes = []
        if not all(r["drained"] for r in rs):
            q = [r["unhandled_end"] for r in rs if not r["drained"]]
            notes.append(f"not drained ({len(q)}/{len(rs)}): {spread(q)} not handled at the deadline")
        if not all(r["warm"] for r in rs):
            notes.append(f"window includes the warm-up ({sum(not r['warm'] for r in rs)}/{len(rs)})")
        if not all(r["counts_add_up"] for r in rs):
            notes.append("COUNTS DO NOT ADD UP")
        refused = {k for r in rs for k in r["refused"]}
        if refused:
            notes.append("refused: " + ", ".join(f"{k} {spread([r['refused'].get(k, 0) for r in rs])}"
                                                 for k in sorted(refused)))
        kb = spread([r.get("recording_bytes_per_meas", float("nan")) / 1e3 for r in rs], ".2f") if rec else "-"
        print(f"{scene:>5} {targets:>7} {'on' if rec else 'off':>9} {spread([r['rate'] for r in rs]):>22} "
              f"{spread(base):>26} "
              f"{spread(ratio, '.4f'):>8} {spread(drain, '.1f'):>14} {kb:>8}  {'; '.join(notes)}")


def print_latency(out: dict[str, Any], *, repeats: int, duration_s: float) -> None:
    print(f"\nend to end, publish-to-estimate latency (ms): scans due on the wall clock for {duration_s:.0f} s, "
          f"each sent as one burst; median (min-max) of {repeats}")
    print(f"{'offered':>8} {'targets':>7} {'recording':>9} {'p50':>22} {'p99':>22} {'max':>22} {'coverage':>18}  notes")
    for rate in sorted({r["rate"] for r in out["latency"]}):
        for rec in (True, False):
            rs = [r for r in out["latency"] if r["rate"] == rate and r["recording"] == rec]
            notes = []
            if not all(r["kept_up"] for r in rs):
                notes.append(f"fell behind ({sum(not r['kept_up'] for r in rs)}/{len(rs)}): "
                             f"{spread([r['unhandled_end'] for r in rs])} not handled at the deadline")
            notes.append(f"publisher late p50 {spread([r['publisher_late_p50_ms'] for r in rs], '.2f')} ms, "
                         f"burst {spread([r['burst_p50_ms'] for r in rs], '.2f')} ms")
            print(f"{rate:>8} {rs[0]['targets']:>7} {'on' if rec else 'off':>9} {lat_cell(rs, 'p50_ms'):>22} "
                  f"{lat_cell(rs, 'p99_ms'):>22} {lat_cell(rs, 'max_ms'):>22} "
                  f"{spread([r['coverage'] for r in rs], '.2f'):>18}  {'; '.join(notes)}")
