"""The `fusion` command line: parsing, messages and exit codes; the work is done by the modules
each command calls. One module per family of commands:

  serve.py   fusion serve, fusion record      (Zenoh in, files out)
  demo.py    fusion demo                      (service + simulated sensors, then a summary)
  files.py   fusion replay, fusion inspect    (work on recorded files)
  query.py   fusion status, fusion tracks     (ask a running service)
  runner.py  exit codes, one-line errors      (shared with fusion-publish)
  args.py    shared flags and checked value types;  progress.py  progress bars;  report.py  wording
"""

from __future__ import annotations

import argparse

from fusion.cli import args as a
from fusion.cli.runner import EPILOG_EXIT_CODES, Parser, run

DESCRIPTION = """\
Streaming sensor fusion over Zenoh: Kalman/EKF/IMM tracks of many targets, every step recorded
to Rerun files. Start with `fusion demo`; `fusion COMMAND --help` explains each command."""

USAGE_EXAMPLES = """\
a session:
  fusion demo                                   # everything at once, then a summary
  fusion serve -c configs/service.toml          # the service, until Ctrl-C    (terminal 1)
  fusion-publish --scenario mix                 # simulated sensors feeding it (terminal 2)
  fusion status ; fusion tracks                 # ask the running service      (terminal 3)
  fusion inspect recordings/mix.rrd             # summarise a recording

"""


def build_parser() -> argparse.ArgumentParser:
    from fusion.cli import demo, files, query, serve

    p = Parser(prog="fusion", description=DESCRIPTION, epilog=USAGE_EXAMPLES + EPILOG_EXIT_CODES,
               formatter_class=a.Formatter, parents=[a.common_flags(in_subcommand=False)])
    p.add_argument("--version", action="version", version=a.version_text("fusion"))
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", title="commands")
    common = a.common_flags(in_subcommand=True)
    demo.add(sub, common)
    serve.add(sub, common)
    query.add(sub, common)
    files.add(sub, common)
    p.commands = tuple(sub.choices)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of `fusion` (and `python -m fusion`)."""
    try:
        parser = build_parser()
    except BrokenPipeError:  # pragma: no cover - nothing printed yet
        return 141
    return run("fusion", parser, argv)
