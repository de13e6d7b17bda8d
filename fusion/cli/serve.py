"""`fusion serve` (the service) and `fusion record` (raw samples to a stream file)."""

from __future__ import annotations

import argparse
import faulthandler
import signal
import threading
import time
from pathlib import Path
from typing import Any

from fusion.cli import args as a
from fusion.cli.progress import bar, wanted
from fusion.cli.report import counts_line, duration, size

SERVE_DESCRIPTION = """\
Run the fusion service until Ctrl-C (or SIGTERM, or --duration): measurements in over Zenoh
(fusion/NS/meas/*), track estimates out (fusion/NS/tracks/*), every step recorded to rotating
Rerun files (.rrd) with the raw input beside them (.fstream, for `fusion replay`). While it runs,
`fusion status` and `fusion tracks` ask it how it is doing; `kill -USR1 PID` prints every
thread's stack to stderr (for a service that seems stuck) and it goes on. A scenario file
(configs/scenarios/NAME.toml) works as a configuration too: its [service] table is used."""

SERVE_EXAMPLES = """\
examples:
  fusion serve -c configs/service.toml
  fusion serve -c configs/scenarios/radar2d.toml --duration 60 --recordings /tmp/rec
  fusion serve -c configs/service.toml -l tcp/127.0.0.1:7448       # listen on another port
  fusion serve -c configs/service.toml -m client -e tcp/ROUTER:7447  # join a Zenoh router"""

RECORD_DESCRIPTION = """\
Record every measurement, control input and truth sample published on a namespace, with its
arrival time, to a stream file (.fstream) that `fusion replay` feeds through the tracker. Runs
until Ctrl-C or --duration. Needs something to connect to: by default the `fusion serve` on this
machine."""

RECORD_EXAMPLES = """\
examples:
  fusion record                                   # to recordings/demo-<time>.fstream until Ctrl-C
  fusion record -o recordings/run1.fstream --duration 60 -n demo
  fusion record -l tcp/127.0.0.1:7450             # be the listening peer publishers connect to"""


def add(sub: Any, common: argparse.ArgumentParser) -> None:
    sp = sub.add_parser("serve", parents=[common], help="run the fusion service",
                        description=SERVE_DESCRIPTION, epilog=SERVE_EXAMPLES, formatter_class=a.Formatter)
    sp.add_argument("-c", "--config", required=True, type=Path, metavar="FILE",
                    help="service TOML: configs/service.toml, or a scenario file (required)")
    a.add_zenoh_flags(sp, config_file=False, default="Default: the config's [zenoh] table (the shipped configs: a peer "
                                  "listening on tcp/127.0.0.1:7447).")
    a.add_namespace(sp, "the config's namespace")
    sp.add_argument("--recordings", type=Path, metavar="DIR",
                    help="folder for the .rrd and .fstream files (default: the config's [recording] directory)")
    sp.add_argument("--duration", type=a.positive_float, metavar="S", help="stop after S seconds (default: run "
                                                                           "until Ctrl-C)")
    sp.add_argument("--connect-wait", type=a.non_negative_float, metavar="S",
                    help="a client keeps trying to reach its peer or router for S seconds at start, with backoff "
                         "(default: the config's [zenoh] connect_wait_s, 30; 0: try once)")
    sp.set_defaults(func=serve)

    rp = sub.add_parser("record", parents=[common], help="record measurement and truth samples to a .fstream",
                        description=RECORD_DESCRIPTION, epilog=RECORD_EXAMPLES, formatter_class=a.Formatter)
    rp.add_argument("-o", "--out", type=Path, metavar="FILE",
                    help="the .fstream file to write (default: recordings/NS-<UTC time>.fstream)")
    a.add_namespace(rp, "demo", default="demo")
    a.add_zenoh_flags(rp, default=a.CLIENT_DEFAULT)
    rp.add_argument("--duration", type=a.positive_float, metavar="S",
                    help="stop after S seconds (default: until Ctrl-C)")
    rp.set_defaults(func=record)


def serve(args: argparse.Namespace) -> int:
    from fusion.io.allocator import settle_allocator

    settle_allocator()  # before rerun is loaded: see fusion.io.allocator for the measured saw-tooth
    import msgspec

    from fusion.config import load_service_config

    path = a.input_file(args.config, "configuration file", "the shipped one is configs/service.toml")
    cfg = load_service_config(path)
    zc = a.zenoh_overrides(args, cfg.zenoh)
    if args.connect_wait is not None:
        zc = msgspec.structs.replace(zc, connect_wait_s=args.connect_wait)
    mode, listen, connect = zc.mode, zc.listen, zc.connect
    cfg = msgspec.structs.replace(cfg, zenoh=zc)
    if args.namespace:
        cfg = msgspec.structs.replace(cfg, namespace=args.namespace)
    from fusion.io.blas import pin_blas_threads
    from fusion.service import Service

    pin_blas_threads()
    svc = Service(cfg, recording_dir=args.recordings)
    signal.signal(signal.SIGTERM, lambda *_: svc.stop())
    signal.signal(signal.SIGINT, lambda *_: svc.stop())
    if hasattr(signal, "SIGUSR1"):  # every thread's stack to stderr, even with the loop stuck in C code
        faulthandler.register(signal.SIGUSR1, all_threads=True, chain=False)
    t0 = time.monotonic()
    svc.open()
    if svc.session is None:  # stopped while connecting
        raise KeyboardInterrupt
    from fusion.io.gc_tuning import settle_garbage_collector

    settle_garbage_collector()  # after start-up: see fusion.io.gc_tuning for the measured cost
    where = f"listening on {', '.join(listen)}" if mode == "peer" else f"connected to {', '.join(connect)}"
    rec = f"recording to {svc.sink.path}" if svc.sink is not None else "not recording"
    print(f"fusion serving namespace {cfg.namespace!r} ({where}); {rec}; Ctrl-C to stop", flush=True)
    code = svc.run(duration_s=args.duration)
    st = svc.status_dict()
    print(f"stopped after {duration(time.monotonic() - t0)}: {counts_line(st['counts'])}")
    for f in _written(svc):
        print(f"  wrote {f} ({size(f.stat().st_size)})")
    return code


def _written(svc: Any) -> list[Path]:
    files = list(getattr(svc.sink, "files", [])) or ([svc.sink.path] if svc.sink is not None else [])
    if svc.stream is not None:
        files.append(svc.stream.path)
    return [f for f in files if f.exists()]


def record(args: argparse.Namespace) -> int:
    zc = a.client_zenoh(args)
    stamp = time.strftime("%Y%m%dT%H%M%S", time.gmtime())
    out = a.output_file(args.out or Path("recordings") / f"{args.namespace}-{stamp}.fstream", "stream file")
    import zenoh

    from fusion.io.recorder import Recorder
    from fusion.io.zenoh_bus import zenoh_session_config

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    deadline = None if args.duration is None else time.monotonic() + args.duration
    with zenoh.open(zenoh_session_config(zc, namespace=args.namespace)) as session:
        rec = Recorder(session, out, namespace=args.namespace)
        print(f"recording fusion/{args.namespace}/meas/*, input/* and truth/* to {out}; Ctrl-C to stop", flush=True)
        with bar(enabled=wanted(args), desc="recorded", unit="sample") as b:
            while not stop.wait(0.2 if deadline is None else max(0.0, min(0.2, deadline - time.monotonic()))):
                b(rec.records)
                if deadline is not None and time.monotonic() >= deadline:
                    break
        missed = rec.missed()
        rec.close()
    print(f"recorded {rec.records} samples to {out}")
    if missed:
        print("lost on the network and not recovered from the publishers' caches: "
              + ", ".join(f"{k} {n}" for k, n in missed.items()))
    if rec.records:
        print(f"replay them with:  fusion replay {out}")
    else:
        print(f"nothing was published on fusion/{args.namespace}/...: is a publisher running (fusion-publish "
              f"--scenario mix), on namespace {args.namespace!r}?")
    return 0
