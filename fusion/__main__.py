"""The `fusion` command line: parsing only; the work is done by the modules it calls."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path


def _inspect(args: argparse.Namespace) -> int:
    from fusion.io.inspect import format_summary, summarise

    s = summarise(args.file)
    print(s.to_json() if args.json else format_summary(s))
    return 0


def _serve(args: argparse.Namespace) -> int:
    import signal

    import msgspec

    from fusion.config import load_service_config
    from fusion.service import Service

    cfg = load_service_config(args.config)
    if args.listen or args.connect or args.mode:
        z = cfg.zenoh
        mode = args.mode or ("client" if args.connect and not args.listen else z.mode)
        zc = msgspec.structs.replace(z, mode=mode, listen=args.listen or (z.listen if mode == "peer" else []),
                                     connect=args.connect or z.connect)  # keeps [zenoh.tls] and access control
        cfg = msgspec.structs.replace(cfg, zenoh=zc)
    if args.namespace:
        cfg = msgspec.structs.replace(cfg, namespace=args.namespace)
    svc = Service(cfg, recording_dir=args.recordings)
    signal.signal(signal.SIGTERM, lambda *_: svc.stop())
    signal.signal(signal.SIGINT, lambda *_: svc.stop())
    svc.open()
    print(f"fusion serving namespace {cfg.namespace!r}; recording to {svc.sink.path if svc.sink else 'nothing'}",
          flush=True)
    return svc.run(duration_s=args.duration)


def _record(args: argparse.Namespace) -> int:
    import signal
    import threading

    import zenoh

    from fusion.io.recorder import Recorder
    from fusion.io.zenoh_bus import cli_zenoh_config, zenoh_session_config

    conf = zenoh_session_config(cli_zenoh_config(zenoh_file=args.zenoh_config, listen=args.listen,
                                                 connect=args.connect))
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    with zenoh.open(conf) as session:
        rec = Recorder(session, args.out, namespace=args.namespace)
        print(f"recording fusion/{args.namespace}/meas/* and truth/* to {args.out}", flush=True)
        stop.wait(args.duration)
        rec.close()
    print(f"recorded {rec.frames} samples")
    return 0


def _demo(args: argparse.Namespace) -> int:
    # The demo drives the simulated sensors: the one place the CLI reaches into publishers/.
    from publishers.demo import demo_report, run_demo

    if not args.verbose:  # refusals are summarised at the end; keep the terminal for that
        logging.getLogger("fusion.pipeline").setLevel(logging.ERROR)
    speed = 0.0 if args.speed == "max" else float(args.speed)
    r = run_demo(scenario=args.scenario, duration_s=args.duration, out=args.out, seed=args.seed, speed=speed)
    print(demo_report(r))
    return 0


def _replay(args: argparse.Namespace) -> int:
    from fusion.replay import replay

    n = replay(args.stream, config=args.config, out=args.out, estimates=args.estimates, realtime=args.realtime,
               progress=sys.stderr.isatty())
    print(f"replayed {n.records} samples: {n.estimates} estimates; recording {args.out}"
          + (f"; estimates {args.estimates}" if args.estimates else ""))
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="fusion", description="Streaming sensor fusion over Zenoh.")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", required=True)

    sp = sub.add_parser("serve", help="run the fusion service")
    sp.add_argument("--config", required=True, type=Path, help="service TOML (see configs/)")
    sp.add_argument("--mode", choices=["peer", "client"], help="override zenoh mode")
    sp.add_argument("--listen", action="append", help="zenoh endpoint to listen on (repeatable)")
    sp.add_argument("--connect", action="append", help="zenoh endpoint to connect to (repeatable)")
    sp.add_argument("--namespace", help="override the key namespace")
    sp.add_argument("--recordings", type=Path, help="folder for .rrd files (default: the config's)")
    sp.add_argument("--duration", type=float, help="stop after this many seconds")
    sp.set_defaults(func=_serve)

    dp = sub.add_parser("demo", help="run the service and simulated sensors together, then summarise")
    dp.add_argument("--scenario", default="mix", help="mix (default) or a reference scenario: radar2d, cv1d_a, ...")
    dp.add_argument("--duration", type=float, default=30.0, help="seconds of scenario time (default 30)")
    dp.add_argument("--out", type=Path, default=Path("recordings/demo.rrd"), help="the recording to write")
    dp.add_argument("--seed", type=int, help="override the scenario's seed")
    dp.add_argument("--speed", default="10", help="times real time (default 10), or max")
    dp.set_defaults(func=_demo)

    yp = sub.add_parser("replay", help="feed a recorded stream through the tracker")
    yp.add_argument("stream", type=Path, help="a .fstream (from the service or fusion record) or a .jsonl")
    yp.add_argument("--config", type=Path, help="service or scenario TOML (default: found from the stream's namespace)")
    yp.add_argument("--out", type=Path, default=Path("recordings/replay.rrd"), help="the recording to write")
    yp.add_argument("--estimates", type=Path, help="also write every estimate to this .jsonl")
    yp.add_argument("--realtime", action="store_true", help="pace at the recorded arrival times")
    yp.set_defaults(func=_replay)

    rp = sub.add_parser("record", help="record measurement and truth samples to a stream file")
    rp.add_argument("--out", required=True, type=Path, help="the .fstream file to write")
    rp.add_argument("--namespace", default="demo")
    rp.add_argument("--connect", action="append", help="zenoh endpoint to connect to (default tcp/127.0.0.1:7447)")
    rp.add_argument("--listen", action="append", help="listen as a peer instead of connecting")
    rp.add_argument("--zenoh-config", type=Path, help="TOML with a [zenoh] table: endpoints, TLS files, identity")
    rp.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")
    rp.set_defaults(func=_record)

    ip = sub.add_parser("inspect", help="summarise a recording (.rrd) headlessly")
    ip.add_argument("file", type=Path)
    ip.add_argument("--json", action="store_true", help="print JSON for scripts")
    ip.set_defaults(func=_inspect)

    args = p.parse_args(argv)
    from fusion.io.blas import pin_blas_threads

    pin_blas_threads()
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
