"""`fusion demo`: the service and simulated sensors together, then a summary. The one place the
command line reaches into publishers/ (which drives the simulated sensors)."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
from pathlib import Path
from typing import Any

from fusion.cli import args as a
from fusion.cli.progress import bar, status, wanted
from fusion.cli.runner import CliError, Exit

DESCRIPTION = """\
Run the service and the simulated sensors of a scenario together over Zenoh on loopback
(nothing else needs to run), accelerated, then print a summary. Writes the recording
(default recordings/<scenario>.rrd) and the raw input beside it (<same name>.fstream, for
`fusion replay`). Ctrl-C stops early and still prints the summary so far; a second Ctrl-C
aborts at once."""

EXAMPLES = """\
examples:
  fusion demo                                  # mix, the whole scenario (60 s) at 10x
  fusion demo -s radar2d --speed max           # a reference scenario, as fast as possible
  fusion demo -s mix --duration 300 --speed max -o /tmp/long.rrd --seed 7"""


def scenario_names() -> list[str]:
    from publishers.spec import CONFIG_DIR

    return sorted(p.stem for p in CONFIG_DIR.glob("*.toml"))


def add(sub: Any, common: argparse.ArgumentParser) -> None:
    names = scenario_names()
    dp = sub.add_parser("demo", parents=[common], help="run the service and simulated sensors together, then "
                                                       "summarise", description=DESCRIPTION, epilog=EXAMPLES,
                        formatter_class=a.Formatter)
    dp.add_argument("-s", "--scenario", default="mix", type=a.choice(names, "scenario"), metavar="NAME",
                    help=f"one of: {', '.join(names)} (default: mix)")
    dp.add_argument("--duration", type=a.positive_float, metavar="S",
                    help="seconds of scenario time (default: the whole scenario)")
    dp.add_argument("-o", "--out", type=Path, metavar="FILE.rrd",
                    help="the recording to write; the .fstream goes beside it (default: recordings/<scenario>.rrd)")
    dp.add_argument("--seed", type=a.seed, metavar="N", help="override the scenario's seed (default: the scenario's)")
    dp.add_argument("--speed", type=a.speed, default=10.0, metavar="X|max",
                    help="times real time, or max for as fast as possible (default: 10)")
    dp.set_defaults(func=demo)


def _on_interrupt(stop: threading.Event, out: Path) -> None:
    """First Ctrl-C: stop publishing, let the service finish and close its files. Second: abort."""

    def abort(*_: object) -> None:
        sys.stderr.write(f"\nfusion demo: aborted; {out} may lack its last steps and its footer\n")
        sys.stderr.flush()
        os._exit(Exit.INTERRUPTED)

    def first(*_: object) -> None:
        stop.set()
        signal.signal(signal.SIGINT, abort)
        sys.stderr.write("\nstopping: finishing what was received and closing the files (Ctrl-C again to abort "
                         "now)\n")
        sys.stderr.flush()

    signal.signal(signal.SIGINT, first)
    signal.signal(signal.SIGTERM, first)


def demo(args: argparse.Namespace) -> int:
    if args.out is not None and args.out.suffix != ".rrd":
        raise CliError(Exit.USAGE, f"--out {args.out}: a recording's name ends in .rrd (the .fstream goes beside it)",
                       where="fusion demo")
    if not args.verbose:  # refusals and service start/stop are in the summary; keep the terminal for it
        logging.getLogger("fusion.pipeline").setLevel(logging.ERROR)
        logging.getLogger("fusion.service").setLevel(logging.WARNING)
    from fusion.io.blas import pin_blas_threads
    from publishers.demo import default_out, demo_report, run_demo

    pin_blas_threads()
    out = a.output_file(args.out or default_out(args.scenario), "recording")
    stop = threading.Event()
    span = "the whole scenario" if args.duration is None else f"{args.duration:g} s of scenario time"
    status(args, f"demo {args.scenario}: simulating {span} ...")
    _on_interrupt(stop, out)
    with bar(enabled=wanted(args), desc=f"demo {args.scenario}", unit="sample") as b:
        r = run_demo(scenario=args.scenario, duration_s=args.duration, out=out, seed=args.seed, speed=args.speed,
                     stop=stop, progress=b)
    print(demo_report(r))
    if r.interrupted:
        raise CliError(Exit.INTERRUPTED, "interrupted: the summary above covers what was processed; the files "
                                         "written are complete")
    return 0
