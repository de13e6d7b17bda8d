"""`fusion-publish`: stream a scenario over Zenoh (argument parsing only)."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from fusion.io.zenoh_bus import DEFAULT_ENDPOINT, cli_zenoh_config, zenoh_session_config
from publishers.publish import publish
from publishers.spec import load_scenario_file, scenario_path
from publishers.stream import build_stream


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="fusion-publish",
                                description="Stream a scenario's measurements and truth over Zenoh.")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--scenario", help="a scenario of configs/scenarios/ (mix, radar2d, cv1d_a, ...)")
    g.add_argument("--config", type=Path, help="a scenario TOML file")
    p.add_argument("--speed", default="1", help="1 = real time, 10 = ten times faster, max = as fast as possible")
    p.add_argument("--seed", type=int, help="override the scenario's seed")
    p.add_argument("--duration", type=float, help="stream only the first SECONDS of sensor time")
    p.add_argument("--connect", action="append", help=f"zenoh endpoint to connect to (default {DEFAULT_ENDPOINT})")
    p.add_argument("--listen", action="append", help="listen as a peer instead of connecting")
    p.add_argument("--zenoh-config", type=Path, help="TOML with a [zenoh] table: endpoints, TLS files, identity")
    p.add_argument("--namespace", help="key namespace (default: the scenario's service namespace)")
    p.add_argument("--relative-time", action="store_true", help="sensor times from 0 instead of the wall clock")
    args = p.parse_args(argv)
    from fusion.io.blas import pin_blas_threads

    pin_blas_threads()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")

    import msgspec

    sf = load_scenario_file(args.config or scenario_path(args.scenario))
    spec = sf.scenario
    if args.seed is not None:
        spec = msgspec.structs.replace(spec, seed=args.seed)
    if args.duration is not None:
        spec = msgspec.structs.replace(spec, duration_s=args.duration)
    ns = args.namespace or sf.service.namespace
    t0 = 0 if args.relative_time else time.time_ns() // 1_000_000 * 1_000_000
    samples, _ = build_stream(spec, namespace=ns, t0_ns=t0)
    speed = 0.0 if args.speed == "max" else float(args.speed)
    conf = zenoh_session_config(cli_zenoh_config(zenoh_file=args.zenoh_config, listen=args.listen,
                                                 connect=args.connect))
    import zenoh

    with zenoh.open(conf) as session:
        try:
            counts = publish(session, samples, speed=speed)
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
            return 130
    print(f"published {dict(sorted(counts.items()))} on fusion/{ns}/...")
    return 0


if __name__ == "__main__":
    sys.exit(main())
