"""`python -m bench [--quick] [--only e2e,core,tracker,gospa,recording,intake,late]`: every benchmark, one command.
`--only soak` (never in the default run): the service's memory over `--soak-s` seconds, sampled
every `--soak-every-s` (bench.soak). `--only recording_ab` (never in the default run): the
recording on its own thread against on the loop, `--pairs` interleaved pairs (bench.recording_ab).
`--only tree_ab --base REV` (never in the default run): the working tree's service against the
service of a git revision, `--pairs` interleaved pairs (bench.tree_ab). `--only handover` (never
in the default run): a callback per sample against the service's channel threads, `--pairs`
interleaved pairs (bench.intake_handover). `--only recording_truth` (never in the default run):
the recording's cost fed fast with every target's truth and without any (bench.recording_truth).

Each benchmark measures its baselines in the same run, interleaved, and prints ratios. The
machine's state (other processes) moves absolute figures; the ratios are the comparison.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path


def machine() -> dict[str, str]:
    import numpy as np

    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    info = {"python": platform.python_version(), "numpy": np.__version__, "cpu": cpu, "cores": str(os.cpu_count())}
    try:
        from threadpoolctl import threadpool_info

        info["blas"] = ", ".join(f"{d.get('internal_api')} {d.get('architecture', '')}".strip()
                                 for d in threadpool_info())
    except ImportError:
        pass
    return info


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench")
    p.add_argument("--quick", action="store_true", help="fewer repeats and sizes (~1 minute)")
    p.add_argument("--only", default="e2e,core,tracker,gospa,recording,intake,late",
                   help="comma-separated: e2e, core, tracker, gospa, recording, intake, late;"
                        " soak, recording_ab, tree_ab, handover, recording_truth (not in the default)")
    p.add_argument("--soak-s", type=float, default=600.0, help="duration of the soak (default 600 s)")
    p.add_argument("--soak-every-s", type=float, default=10.0, help="the soak's sampling period (default 10 s)")
    p.add_argument("--pairs", type=int, default=3,
                   help="recording_ab, tree_ab, handover: interleaved pairs (default 3)")
    p.add_argument("--base", default="HEAD", help="tree_ab: the git revision the working tree is compared with")
    p.add_argument("--json", type=Path, help="also write the figures to this file")
    args = p.parse_args(argv)
    from fusion.io.blas import pin_blas_threads

    pin_blas_threads()
    os.environ.setdefault("XDG_CONFIG_HOME", "/tmp/fusion-bench-xdg")
    os.environ.setdefault("XDG_DATA_HOME", "/tmp/fusion-bench-xdg")
    print("machine:", ", ".join(f"{k} {v}" for k, v in machine().items()))
    results: dict[str, object] = {"machine": machine(), "date": time.strftime("%Y-%m-%d")}
    for name in args.only.split(","):
        print()
        t0 = time.perf_counter()
        if name == "e2e":
            from bench import service_e2e

            results["e2e"] = service_e2e.run(quick=args.quick)
        elif name == "soak":
            from bench import soak

            results["soak"] = soak.run_soak(duration_s=args.soak_s, every_s=args.soak_every_s)
        elif name == "recording_ab":
            from bench import recording_ab

            results["recording_ab"] = recording_ab.run(pairs=args.pairs, quick=args.quick)
        elif name == "handover":
            from bench import intake_handover

            results["handover"] = intake_handover.run(pairs=args.pairs, quick=args.quick)
        elif name == "tree_ab":
            from bench import tree_ab

            results["tree_ab"] = tree_ab.run(base=args.base, pairs=args.pairs, quick=args.quick)
        elif name == "core":
            from bench import core_step

            results["core"] = core_step.run(quick=args.quick)
        elif name == "tracker":
            from bench import tracker_scan

            results["tracker"] = tracker_scan.run(quick=args.quick)
        elif name == "gospa":
            from bench import gospa

            results["gospa"] = gospa.run(quick=args.quick)
        elif name == "late":
            from bench import late_data, late_e2e

            results["late"] = late_data.run(quick=args.quick) | late_e2e.run(quick=args.quick)
        elif name == "recording":
            from bench import recording_cost

            results["recording"] = recording_cost.run(quick=args.quick)
        elif name == "recording_truth":
            from bench import recording_truth

            results["recording_truth"] = recording_truth.run(quick=args.quick)
        elif name == "intake":
            from bench import intake_path

            results["intake"] = intake_path.run(quick=args.quick)
        else:
            print(f"unknown benchmark {name!r}", file=sys.stderr)
            return 2
        print(f"({name}: {time.perf_counter() - t0:.0f} s)")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
