"""Running a command: logging, and every expected failure as one line on stderr with its own
exit code (a traceback only with -v/--debug). Shared by `fusion` and `fusion-publish`."""

from __future__ import annotations

import argparse
import logging
import os
import re
import sys
import traceback
from collections.abc import Callable
from enum import IntEnum


class Exit(IntEnum):
    """Exit codes; EPILOG below documents them for --help (and the README repeats them)."""

    OK = 0
    INTERNAL = 1
    USAGE = 2
    CONFIG = 3
    FILE = 4
    LISTEN = 5
    CONNECT = 6
    NO_ANSWER = 7
    INTERRUPTED = 130
    BROKEN_PIPE = 141


EXIT_MEANINGS = {
    Exit.OK: "success",
    Exit.INTERNAL: "internal error (a bug: run again with --debug and report the traceback)",
    Exit.USAGE: "bad command-line arguments",
    Exit.CONFIG: "invalid configuration file (the message names the file, line and key)",
    Exit.FILE: "a file is missing, unreadable, unwritable or not of the expected kind",
    Exit.LISTEN: "Zenoh cannot listen or start (address in use, bad endpoint)",
    Exit.CONNECT: "Zenoh cannot connect: nothing is listening at the endpoint",
    Exit.NO_ANSWER: "no fusion service answered the query",
    Exit.INTERRUPTED: "interrupted (Ctrl-C); what was written so far is complete and named",
    Exit.BROKEN_PIPE: "the output pipe closed early (e.g. `| head`); nothing is printed",
}

EPILOG_EXIT_CODES = "exit codes:\n" + "\n".join(f"  {int(c):>3}  {t}" for c, t in EXIT_MEANINGS.items())


class CliError(Exception):
    """An expected failure: one line for the person at the terminal, and an exit code."""

    def __init__(self, code: Exit, message: str, *, where: str | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.where = where  # the command it concerns, when known better than the runner knows it


_RUST_LOCATION = re.compile(r"\s*at /\S+?\.rs:\d+\.?")


def zenoh_message(text: str) -> str:
    """A Zenoh error without the Rust source locations it carries."""
    return " ".join(_RUST_LOCATION.sub("", text).split()).rstrip(". ")


def explain_zenoh(exc: BaseException, *, where: str = "") -> CliError:
    """A Zenoh error as a CliError that says what to do (`where`: the command, e.g. "fusion serve")."""
    text = zenoh_message(str(exc))
    if m := re.search(r"bound to (\S+?):? \[.*(Address already in use|Permission denied|Cannot assign requested "
                      r"address)", text):
        endpoint, why = m.group(1), m.group(2).lower()
        hint = ("another program (perhaps another `fusion serve`) listens there: stop it, or listen elsewhere "
                "with -l tcp/127.0.0.1:PORT") if "in use" in why else "listen on another address with -l"
        return CliError(Exit.LISTEN, f"cannot listen on {endpoint}: {why}; {hint}")
    if m := re.search(r"Unable to connect to any of \[(.*)\]", text):
        eps = ", ".join(re.findall(r"\(([^()]+)\)", m.group(1))) or m.group(1)
        if where.endswith("serve"):
            return CliError(Exit.CONNECT, f"cannot connect to {eps}: nothing is listening there (tried for "
                                          "[zenoh] connect_wait_s); start the peer or router it joins first, or "
                                          "serve as a peer with -m peer -l tcp/127.0.0.1:PORT")
        return CliError(Exit.CONNECT, f"cannot connect to {eps}: nothing is listening there; start the service "
                                      "first (fusion serve -c configs/service.toml), or give its endpoint with -e")
    if "lookup address" in text:
        return CliError(Exit.LISTEN, f"an endpoint names an unknown host ({text}); use an address like "
                                     "tcp/127.0.0.1:7447")
    return CliError(Exit.LISTEN, f"Zenoh could not start: {text}")


def _is_zenoh_error(exc: BaseException) -> bool:
    return type(exc).__module__.split(".")[0] == "zenoh"


def classify(exc: BaseException, *, where: str = "") -> CliError:
    """Map an exception to the CliError a person sees (anything unexpected is INTERNAL)."""
    from fusion.errors import ConfigError, FusionError, InputError

    if isinstance(exc, CliError):
        return exc
    if isinstance(exc, ConfigError):
        return CliError(Exit.CONFIG, str(exc))
    if _is_zenoh_error(exc):
        return explain_zenoh(exc, where=where)
    if type(exc).__name__ == "NoAnswerError":
        return CliError(Exit.NO_ANSWER, str(exc))
    if isinstance(exc, InputError | FusionError):
        return CliError(Exit.FILE, str(exc))
    if isinstance(exc, OSError) and exc.filename is not None:
        return CliError(Exit.FILE, f"{exc.filename}: {exc.strerror or exc}")
    # the Rerun writer's file errors come as RuntimeError("Failed to create file: ... (os error N), path: P")
    rerun_io = type(exc).__module__.split(".")[0] in ("rerun", "rerun_bindings") or "(os error " in str(exc)
    if rerun_io and (m := re.search(r"(Failed to \w+ file|No space left on device|Permission denied)[^,]*"
                                    r"(?:, path: (\S+))?", str(exc))):
            where = f"{m.group(2)}: " if m.group(2) else ""
            return CliError(Exit.FILE, f"{where}cannot write the recording ({m.group(0).split(', path')[0]}); "
                                       "free some space or give another folder (--recordings / -o)")
    return CliError(Exit.INTERNAL, f"internal error: {type(exc).__name__}: {exc} "
                                   "(run again with --debug for the traceback, and please report it)")


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: `fusion demo: error: ...; see fusion demo --help`. A parser
    of commands (`commands` set) run without one names them."""

    commands: tuple[str, ...] = ()

    def error(self, message: str) -> None:  # type: ignore[override]
        if self.commands and message.startswith("the following arguments are required: COMMAND"):
            message = f"which command? one of {', '.join(self.commands)} (start with `{self.prog} demo`)"
        raise CliError(Exit.USAGE, f"{message} (see {self.prog} --help)", where=self.prog)


def configure_logging(*, verbose: bool, quiet: bool) -> None:
    level = logging.DEBUG if verbose else logging.WARNING if quiet else logging.INFO
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def run(prog: str, parser: argparse.ArgumentParser, argv: list[str] | None,
        setup: Callable[[argparse.Namespace], None] | None = None) -> int:
    """Parse, run args.func(args), and turn every failure into one line and an exit code."""
    debug = any(a in ("-v", "--verbose", "--debug") for a in (sys.argv[1:] if argv is None else argv))
    where = prog
    try:
        args = parser.parse_args(argv)
        where = f"{prog} {args.command}" if getattr(args, "command", None) else prog
        debug = bool(getattr(args, "verbose", False))
        configure_logging(verbose=debug, quiet=bool(getattr(args, "quiet", False)))
        if setup is not None:
            setup(args)
        code = int(args.func(args))
        sys.stdout.flush()
        return code
    except BrokenPipeError:
        _silence_stdout()
        return Exit.BROKEN_PIPE
    except (KeyboardInterrupt, Exception) as e:
        err = (CliError(Exit.INTERRUPTED, "interrupted") if isinstance(e, KeyboardInterrupt)
               else classify(e, where=where))
        if debug and not (isinstance(e, CliError) and e.code == Exit.USAGE):
            traceback.print_exc()
        try:
            sys.stdout.flush()
        except BrokenPipeError:
            _silence_stdout()
        where = err.where or where
        if err.code == Exit.USAGE and "--help" not in str(err):
            err = CliError(err.code, f"{err} (see {where} --help)")
        print(f"{where}: error: {err}" if err.code != Exit.INTERRUPTED else f"{where}: {err}", file=sys.stderr)
        return err.code
    finally:
        from fusion.io.ratelimit import flush_all

        flush_all()


def _silence_stdout() -> None:
    """After EPIPE: point stdout at /dev/null so the interpreter's final flush stays quiet."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
