"""`fusion-publish`: stream a scenario over Zenoh (argument parsing only; errors, exit codes and
progress as in `fusion`, see fusion.cli)."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from pathlib import Path

from fusion.cli import args as a
from fusion.cli.progress import bar, status, wanted
from fusion.cli.runner import EPILOG_EXIT_CODES, CliError, Exit, Parser, run

DESCRIPTION = """\
Simulated sensors: stream a scenario's measurements (fusion/NS/meas/SENSOR) and truth
(fusion/NS/truth/TARGET) over Zenoh, paced by their arrival times, to a running `fusion serve`.
Ctrl-C stops early and says how much was published."""

EXAMPLES = """\
examples:
  fusion-publish --scenario mix                       # to the fusion serve on this machine, real time
  fusion-publish -s radar2d --speed max --relative-time
  fusion-publish -c my_scenario.toml -e tcp/127.0.0.1:7448 --duration 60

"""


def build_parser() -> argparse.ArgumentParser:
    from publishers.spec import CONFIG_DIR

    names = sorted(q.stem for q in CONFIG_DIR.glob("*.toml"))
    p = Parser(prog="fusion-publish", description=DESCRIPTION, epilog=EXAMPLES + EPILOG_EXIT_CODES,
               formatter_class=a.Formatter, parents=[a.common_flags(in_subcommand=False)])
    p.add_argument("--version", action="version", version=a.version_text("fusion-publish"))
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("-s", "--scenario", type=a.choice(names, "scenario"), metavar="NAME",
                   help=f"a scenario of configs/scenarios/: {', '.join(names)}")
    g.add_argument("-c", "--config", type=Path, metavar="FILE", help="a scenario TOML file (instead of --scenario)")
    p.add_argument("--speed", type=a.speed, default=1.0, metavar="X|max",
                   help="1 = real time, 10 = ten times faster, max = as fast as possible (default: 1)")
    p.add_argument("--seed", type=a.seed, metavar="N", help="override the scenario's seed (default: the scenario's)")
    p.add_argument("--duration", type=a.positive_float, metavar="S",
                   help="stream only the first S seconds of sensor time (default: the whole scenario)")
    a.add_namespace(p, "the scenario's [service] namespace")
    a.add_zenoh_flags(p, default=a.CLIENT_DEFAULT)
    p.add_argument("--relative-time", action="store_true",
                   help="sensor times from 0 instead of the wall clock (default: wall clock)")
    p.set_defaults(func=publish_scenario, command=None)
    return p


def publish_scenario(args: argparse.Namespace) -> int:
    import msgspec

    from fusion.io.blas import pin_blas_threads
    from publishers.spec import load_scenario_file, scenario_path

    zc = a.client_zenoh(args)
    path = (a.input_file(args.config, "scenario file", "the shipped ones are in configs/scenarios/")
            if args.config else scenario_path(args.scenario))
    sf = load_scenario_file(path)
    spec = sf.scenario
    if args.seed is not None:
        spec = msgspec.structs.replace(spec, seed=args.seed)
    if args.duration is not None:
        spec = msgspec.structs.replace(spec, duration_s=args.duration)
    ns = args.namespace or sf.service.namespace
    pin_blas_threads()
    import zenoh

    from fusion.io.zenoh_bus import zenoh_session_config
    from publishers.publish import boot_epoch, publish, sent_words
    from publishers.stream import build_stream

    # Zenoh first: nothing to connect to is found out before the stream is built
    with zenoh.open(zenoh_session_config(zc, namespace=ns)) as session:
        status(args, f"fusion-publish: building the stream of {path.stem} ...")
        t0 = 0 if args.relative_time else time.time_ns() // 1_000_000 * 1_000_000
        samples, _ = build_stream(spec, namespace=ns, t0_ns=t0, epoch=boot_epoch())
        stop = threading.Event()
        signal.signal(signal.SIGINT, lambda *_: stop.set())
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        with bar(enabled=wanted(args), desc=f"publish {path.stem}", unit="sample") as b:
            counts = publish(session, samples, speed=args.speed, stop=stop, progress=lambda n: b(n, len(samples)))
    print(f"published {sent_words(counts)} on fusion/{ns}/... ({sum(counts.values())} of {len(samples)} samples)")
    if stop.is_set():
        raise CliError(Exit.INTERRUPTED, "interrupted before the end of the scenario")
    return 0


def main(argv: list[str] | None = None) -> int:
    return run("fusion-publish", build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
