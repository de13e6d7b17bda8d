"""Argument pieces shared by every command: checked value types, Zenoh flags in the style of
zenoh's own tools (-m/--mode, -e/--connect, -l/--listen), verbosity, input-file checks."""

from __future__ import annotations

import argparse
import difflib
import os
import tempfile
from collections.abc import Callable, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

from fusion.cli.runner import CliError, Exit

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"  # fusion.io.zenoh_bus.DEFAULT_ENDPOINT, without importing it


class Formatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the line breaks of descriptions and example epilogs."""

    def __init__(self, prog: str) -> None:
        super().__init__(prog, max_help_position=34)


def common_flags(*, in_subcommand: bool) -> argparse.ArgumentParser:
    """-v/--debug and -q, accepted before and after the subcommand. In a subcommand their
    defaults are SUPPRESS, so that `fusion -v demo` is not undone by the subparser."""
    p = argparse.ArgumentParser(add_help=False)
    d = argparse.SUPPRESS if in_subcommand else False
    p.add_argument("-v", "--verbose", "--debug", dest="verbose", action="store_true", default=d,
                   help="debug logging, and the full traceback of an error")
    p.add_argument("-q", "--quiet", action="store_true", default=d,
                   help="no progress bars; log only warnings and errors")
    return p


def version_text(prog: str) -> str:
    def v(dist: str) -> str:
        try:
            return metadata.version(dist)
        except metadata.PackageNotFoundError:
            return "not installed"

    import platform

    return (f"{prog} {v('fusion')} (eclipse-zenoh {v('eclipse-zenoh')}, rerun-sdk {v('rerun-sdk')}, "
            f"Python {platform.python_version()})")


def positive_float(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not x > 0 or x == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number of seconds, got {text!r}")
    return x


def non_negative_float(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not x >= 0 or x == float("inf"):
        raise argparse.ArgumentTypeError(f"must be 0 or a positive number of seconds, got {text!r}")
    return x


def speed(text: str) -> float:
    """'max' (0.0: as fast as possible) or a positive factor of real time."""
    if text.strip().lower() == "max":
        return 0.0
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither a number nor 'max' (e.g. 1, 10, 0.5 or max)") from None
    if not x > 0 or x == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive factor of real time or 'max', got {text!r}")
    return x


def seed(text: str) -> int:
    try:
        x = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if x < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, got {text!r}")
    return x


def choice(names: Sequence[str], what: str) -> Callable[[str], str]:
    """An argument type accepting one of `names`; otherwise the list and the nearest name."""

    def check(text: str) -> str:
        if text in names:
            return text
        close = difflib.get_close_matches(text, names, n=1, cutoff=0.5)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise argparse.ArgumentTypeError(f"no {what} {text!r}{hint} (choose from {', '.join(names)})")

    check.__name__ = what
    return check


def endpoint(text: str) -> str:
    """A Zenoh endpoint `<protocol>/<address>`, e.g. tcp/127.0.0.1:7447."""
    proto, sep, addr = text.partition("/")
    if not sep or not proto or not addr:
        raise argparse.ArgumentTypeError(f"{text!r} is not a Zenoh endpoint: write <protocol>/<address>, "
                                         f"e.g. tcp/{text if ':' in text else '127.0.0.1:7447'}")
    return text


def add_zenoh_flags(p: argparse.ArgumentParser, *, default: str, config_file: bool = True) -> None:
    """-m/--mode, -e/--connect, -l/--listen as zenoh's own example programs spell them, and
    --zenoh-config for TLS files and an identity (a TOML file with a [zenoh] table)."""
    g = p.add_argument_group("zenoh", f"How to join Zenoh. {default}")
    if config_file:
        g.add_argument("--zenoh-config", type=Path, metavar="FILE",
                       help="a TOML file with a [zenoh] table: endpoints, TLS certificates, identity "
                            "(see SECURITY.md); -m/-e/-l override its endpoints (default: none, plain TCP)")
    g.add_argument("-m", "--mode", choices=["peer", "client"],
                   help="peer (listens, with -l) or client (connects, with -e)")
    g.add_argument("-e", "--connect", action="append", type=endpoint, metavar="ENDPOINT",
                   help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)")
    g.add_argument("-l", "--listen", action="append", type=endpoint, metavar="ENDPOINT",
                   help="endpoint to listen on, e.g. tcp/127.0.0.1:7448 (repeatable)")


CLIENT_DEFAULT = f"Default: a client of {DEFAULT_ENDPOINT} (where `fusion serve` listens)."


def client_session(args: argparse.Namespace) -> tuple[str, list[str], list[str]]:
    """(mode, listen, connect) for a command that joins an existing service: a client of
    DEFAULT_ENDPOINT unless told otherwise; --listen alone makes a listening peer."""
    mode = args.mode or ("peer" if args.listen else "client")
    listen = list(args.listen or [])
    connect = list(args.connect or ([] if listen or mode == "peer" else [DEFAULT_ENDPOINT]))
    if mode == "peer" and not listen:
        raise CliError(Exit.USAGE, "a peer needs an endpoint to listen on: add -l tcp/127.0.0.1:PORT "
                                   "(or use -m client -e ENDPOINT)")
    if mode == "client" and listen:
        raise CliError(Exit.USAGE, "a client does not listen: drop -l, or use -m peer")
    return mode, listen, connect


def zenoh_overrides(args: argparse.Namespace, z: Any) -> Any:
    """The ZenohConfig `z` with the command line's -m/-e/-l applied (its TLS and access-control
    settings kept)."""
    import msgspec

    mode = args.mode or ("client" if args.connect and not args.listen else z.mode)
    if mode == "client" and args.listen:
        raise CliError(Exit.USAGE, "a client does not listen: drop -l, or use -m peer")
    listen = list(args.listen or (z.listen if mode == "peer" else []))
    connect = list(args.connect or z.connect)
    if mode == "client" and not connect:
        raise CliError(Exit.USAGE, "a client needs an endpoint to connect to: add -e tcp/HOST:PORT")
    if mode == "peer" and not listen:
        raise CliError(Exit.USAGE, "a peer needs an endpoint to listen on: add -l tcp/127.0.0.1:PORT")
    return msgspec.structs.replace(z, mode=mode, listen=listen, connect=connect)


def client_zenoh(args: argparse.Namespace) -> Any:
    """How a command that joins an existing service connects: its --zenoh-config file with the
    flags applied, or else a client of DEFAULT_ENDPOINT (--listen alone: a listening peer)."""
    from fusion.config import ZenohConfig
    from fusion.io.zenoh_bus import load_zenoh_file

    if getattr(args, "zenoh_config", None) is None:
        mode, listen, connect = client_session(args)
        return ZenohConfig(mode=mode, listen=listen, connect=connect)
    path = input_file(args.zenoh_config, "zenoh configuration file", "see configs/security/ for examples")
    return zenoh_overrides(args, load_zenoh_file(path))


def input_file(path: Path, what: str, hint: str = "") -> Path:
    """`path` if it is a readable file; else CliError(FILE) saying which and what to do."""
    tail = f"; {hint}" if hint else ""
    if not path.exists():
        raise CliError(Exit.FILE, f"{path}: no such {what}{tail}")
    if path.is_dir():
        raise CliError(Exit.FILE, f"{path}: is a folder, not a {what}{tail}")
    if not os.access(path, os.R_OK):
        raise CliError(Exit.FILE, f"{path}: permission denied (cannot read this {what})")
    return path


def output_file(path: Path, what: str, hint: str = "choose another place with -o") -> Path:
    """`path` if a file can be written there; else CliError(FILE) saying why and what to do.
    The nearest folder of `path` that exists is probed with a temporary file, removed at once
    (nothing is left behind, missing folders are made later by the writer). Run before anything
    starts, so that a bad -o fails in one line instead of after the work."""
    tail = f"; {hint}" if hint else ""
    if path.is_dir():
        raise CliError(Exit.FILE, f"{path}: is a folder; give the {what}'s file name{tail}")
    folder = path.parent.absolute()
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    try:
        if not folder.is_dir():
            raise NotADirectoryError(20, "not a folder")
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".fusion-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise CliError(Exit.FILE, f"{path}: cannot write the {what} there ({e.strerror or e}){tail}") from None
    return path


def magic(path: Path, n: int = 8) -> bytes:
    with path.open("rb") as f:
        return f.read(n)


_NS_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.")


def namespace(text: str) -> str:
    """A namespace usable inside key expressions (fusion.messages.check_id's rule)."""
    if not 1 <= len(text) <= 64 or not set(text) <= _NS_CHARS:
        raise argparse.ArgumentTypeError(f"{text!r}: a namespace is 1-64 of letters, digits, '_', '-', '.'")
    return text


def add_namespace(p: argparse.ArgumentParser, default_text: str, default: str | None = None) -> None:
    p.add_argument("-n", "--namespace", type=namespace, default=default, metavar="NS",
                   help=f"key namespace: keys are fusion/NS/... (default: {default_text})")
