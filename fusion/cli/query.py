"""`fusion status` and `fusion tracks`: ask a running service (its Zenoh queryables)."""

from __future__ import annotations

import argparse
from typing import Any

from fusion.cli import args as a
from fusion.cli.runner import CliError, Exit

STATUS_DESCRIPTION = """\
Ask a running `fusion serve` how it is doing: samples received, applied, dropped as duplicates
and refused (by reason), late ones folded in, estimates published, tracks by status, arrival
latency per sensor, the recording it writes. Queries fusion/NS/status."""

TRACKS_DESCRIPTION = """\
Ask a running `fusion serve` for its confirmed tracks: the latest estimate of each (time, state
in the tracker's layout, position standard deviation, last sensor, NIS). Queries
fusion/NS/snapshot."""


def _examples(cmd: str) -> str:
    return f"""\
examples:
  fusion {cmd}                              # the service on this machine, namespace demo
  fusion {cmd} -n radar2d -e tcp/127.0.0.1:7448
  fusion {cmd} --json                       # for scripts"""


def add(sub: Any, common: argparse.ArgumentParser) -> None:
    for cmd, help_, desc, func in (("status", "ask a running service for its status", STATUS_DESCRIPTION, status),
                                   ("tracks", "ask a running service for its confirmed tracks", TRACKS_DESCRIPTION,
                                    tracks)):
        p = sub.add_parser(cmd, parents=[common], help=help_, description=desc, epilog=_examples(cmd),
                           formatter_class=a.Formatter)
        a.add_namespace(p, "demo", default="demo")
        a.add_zenoh_flags(p, default=a.CLIENT_DEFAULT)
        p.add_argument("--timeout", type=a.positive_float, default=2.0, metavar="S",
                       help="wait at most S seconds for an answer (default: 2)")
        p.add_argument("--json", action="store_true", help="print JSON for scripts instead of text")
        p.set_defaults(func=func)


def _ask(args: argparse.Namespace, what: str) -> Any:
    zc = a.client_zenoh(args)
    import zenoh

    from fusion.io.query import NoAnswerError, query_snapshot, query_status
    from fusion.io.zenoh_bus import zenoh_session_config

    ask = query_status if what == "status" else query_snapshot
    with zenoh.open(zenoh_session_config(zc, namespace=args.namespace)) as session:
        try:
            return ask(session, args.namespace, timeout_s=args.timeout)
        except NoAnswerError as e:
            raise CliError(Exit.NO_ANSWER, f"{e}; is `fusion serve` running with namespace {args.namespace!r}? "
                                           "(choose another with -n NS, another endpoint with -e)") from None


def status(args: argparse.Namespace) -> int:
    from fusion import messages as m
    from fusion.cli.report import format_status

    st = _ask(args, "status")
    print(m.encode_json(st).decode() if args.json else format_status(st, args.namespace))
    return 0


def tracks(args: argparse.Namespace) -> int:
    from fusion import messages as m
    from fusion.cli.report import format_tracks

    snap = _ask(args, "snapshot")
    print(m.encode_json(snap).decode() if args.json else format_tracks(snap, args.namespace))
    return 0
