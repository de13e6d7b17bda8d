"""`fusion replay` (a recorded stream through the tracker) and `fusion inspect` (a recording's
summary): the commands that work on files."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from fusion.cli import args as a
from fusion.cli.progress import bar, wanted
from fusion.cli.report import counts_line, duration, flat_counts
from fusion.cli.runner import CliError, Exit
from fusion.tracking.detection import Reason

RRD_MAGIC = b"RRF2"
STREAM_MAGIC = b"FUSIONST"

REPLAY_DESCRIPTION = """\
Feed a recorded input stream through the same pipeline as the live service, and write a new
recording. Deterministic: the estimates are those the live service published. Streams come
from `fusion demo` and `fusion serve` (a .fstream beside each .rrd), from `fusion record`, or
are a .jsonl file of measurement, control input and truth messages."""

REPLAY_EXAMPLES = """\
examples:
  fusion replay recordings/mix.fstream                     # writes recordings/mix-replay.rrd
  fusion replay run1.fstream -c configs/service.toml -o /tmp/run1.rrd --estimates /tmp/est.jsonl
  fusion replay run1.fstream --realtime                    # paced at the recorded arrival times
  fusion replay recordings/maneuver2d.fstream --smooth     # smoothed tracks beside the filtered ones"""

INSPECT_DESCRIPTION = """\
Summarise a recording (.rrd) without a screen: time span, sensors, a table of the confirmed
tracks (short labels, times in seconds), position RMSE and OSPA/GOSPA against the truth, NIS and
NEES with chi-square verdicts that allow for time correlation (and say what they assume), counts
of late, duplicate and refused samples, events. Only the latest revision of each estimate counts.
Takes one file, several, a folder or a glob: the files of a rotated recording are merged in time
order, and any one of them is summarised on its own. Works on the file of a crashed service too.
Several runs: every recording carries the id of the tracker run that wrote it (the files of a
rotated set share it). Files of different runs are taken as independent runs of the same scenario
(e.g. fusion replay of one scenario's streams with seeds 0..N-1 into separate files): tracks are
listed per run and NIS/NEES are averaged over the runs (the run-averaged NEES at each time is
chi2(n N) / N, and the time average is tested with its correlation-aware interval). One run of a
slowly forgetting filter may hold too few independent samples: its verdict then says
"inconclusive: N effective samples". To look at it: rerun FILE."""

INSPECT_EXAMPLES = """\
examples:
  fusion inspect recordings/mix.rrd
  fusion inspect recordings/mix.rrd --json | python -m json.tool
  fusion inspect recordings/service/          # every file of a rotated recording
  fusion inspect runs/seed-*.rrd              # independent runs: verdicts averaged over them
  fusion inspect old/*.rrd --runs files       # recordings without run ids, one run per file"""


def add(sub: Any, common: argparse.ArgumentParser) -> None:
    yp = sub.add_parser("replay", parents=[common], help="feed a recorded stream through the tracker",
                        description=REPLAY_DESCRIPTION, epilog=REPLAY_EXAMPLES, formatter_class=a.Formatter)
    yp.add_argument("stream", type=Path, metavar="STREAM",
                    help="a .fstream (from fusion demo/serve/record) or a .jsonl")
    yp.add_argument("-c", "--config", type=Path, metavar="FILE",
                    help="service or scenario TOML (default: the scenario whose namespace the stream was recorded "
                         "under)")
    yp.add_argument("-o", "--out", type=Path, metavar="FILE",
                    help="the recording to write (default: STREAM's folder/<STREAM name>-replay.rrd)")
    yp.add_argument("--estimates", type=Path, metavar="FILE", help="also write every estimate to this .jsonl "
                                                                   "(default: none)")
    yp.add_argument("--realtime", action="store_true",
                    help="pace at the recorded arrival times (default: as fast as possible)")
    yp.add_argument("--smooth", action="store_true",
                    help="also run a fixed-interval RTS smoother over each confirmed track and record the "
                         "smoothed estimates beside the filtered ones (tracks/<id>/smoothed/...) (default: off)")
    yp.set_defaults(func=replay)

    ip = sub.add_parser("inspect", parents=[common], help="summarise a recording (.rrd) headlessly",
                        description=INSPECT_DESCRIPTION, epilog=INSPECT_EXAMPLES, formatter_class=a.Formatter)
    ip.add_argument("file", type=str, metavar="FILE", nargs="+",
                    help="recordings (.rrd) written by fusion serve, demo or replay: files, a folder or a glob "
                         "(a rotated set is merged in time order)")
    ip.add_argument("--json", action="store_true", help="print JSON for scripts instead of text")
    ip.add_argument("--runs", choices=("id", "files", "one"), default="id",
                    help="how files are told apart as independent runs: by the run id each recording carries "
                         "(files without one are taken as one run), each file one run, or all files pieces of one "
                         "run (a service restarted from a checkpoint starts a new run id but continues its tracks; "
                         "independent runs merged so would mix tracks that share ids) (default: id)")
    ip.set_defaults(func=inspect)


def _check_kind(path: Path, want: bytes) -> None:
    head = a.magic(path)
    if head.startswith(want):
        return
    if not head:
        raise CliError(Exit.FILE, f"{path}: the file is empty")
    if head.startswith(STREAM_MAGIC):
        raise CliError(Exit.FILE, f"{path}: this is a recorded input stream (.fstream), not a recording; feed it "
                                  f"through the tracker with:  fusion replay {path}")
    if head.startswith(RRD_MAGIC):
        raise CliError(Exit.FILE, f"{path}: this is a Rerun recording (.rrd), not an input stream; summarise it "
                                  f"with:  fusion inspect {path}")
    kind = "a Rerun recording (.rrd)" if want == RRD_MAGIC else "a fusion stream (.fstream)"
    raise CliError(Exit.FILE, f"{path}: not {kind} (it starts with {head[:4]!r})")


def _shown(path: Path | None) -> str:
    """A path as a user reads it: relative to the working directory when under it."""
    if path is None:
        return "?"
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def replay(args: argparse.Namespace) -> int:
    stream = a.input_file(args.stream, "stream file", "fusion demo and fusion serve write one (.fstream) beside "
                                                      "each recording")
    if stream.suffix != ".jsonl":
        _check_kind(stream, STREAM_MAGIC)
    config = None if args.config is None else a.input_file(args.config, "configuration file",
                                                           "give a service or scenario TOML")
    out = a.output_file(args.out or stream.with_name(f"{stream.stem}-replay.rrd"), "recording")
    from fusion.io.blas import pin_blas_threads
    from fusion.replay import replay as run_replay

    pin_blas_threads()
    done = [0, 0]

    t0 = time.monotonic()
    with bar(enabled=wanted(args), desc=f"replay {stream.name}", unit="sample") as b:
        def progress(i: int, n: int) -> None:
            done[:] = [i, n]
            b(i, n)

        try:
            r = run_replay(stream, config=config, out=out, estimates=args.estimates, realtime=args.realtime,
                           progress=progress, smooth=args.smooth)
        except KeyboardInterrupt:
            raise CliError(Exit.INTERRUPTED, f"interrupted after {done[0]} of {done[1]} samples; the partial "
                                             f"recording {out} is complete (fusion inspect {out})") from None
    line = counts_line(flat_counts(r.counts, published=r.estimates))
    cfg = _shown(r.config)
    print(f"replayed {r.records} samples in {duration(time.monotonic() - t0)} with {cfg}: {line}")
    if r.counts.applied == 0 and r.counts.refused.get(Reason.UNKNOWN_SENSOR):
        print(f"hint: {cfg} configures none of the stream's sensors; give the configuration the stream was "
              f"made with: fusion replay {stream} -c FILE")
    if args.smooth:
        rmse = ("" if r.rmse_smoothed_m is None else
                f": position RMSE vs truth filtered {r.rmse_filtered_m:.3f} m, smoothed {r.rmse_smoothed_m:.3f} m")
        print(f"  smoothed {r.smoothed_tracks} tracks{rmse}")
        for tid, why in r.smoothing_failed:
            print(f"  track {tid} not smoothed: {why}")
    print(f"  wrote {out}" + (f" and {args.estimates}" if args.estimates else ""))
    print(f"next:  fusion inspect {out}   or   rerun {out}")
    return 0


def inspect(args: argparse.Namespace) -> int:
    from fusion.io.inspect import expand, format_summary, summarise

    paths = expand(args.file)
    if not paths:
        raise CliError(Exit.FILE, f"{' '.join(args.file)}: no recordings found; fusion demo writes "
                                  "recordings/<scenario>.rrd")
    for p in paths:
        a.input_file(p, "recording", "fusion demo writes recordings/<scenario>.rrd")
        _check_kind(p, RRD_MAGIC)
    try:
        s = summarise(paths, runs_by=args.runs)
    except RuntimeError as e:
        raise CliError(Exit.FILE, f"{' '.join(map(str, paths))}: cannot read this recording: {e}") from None
    print(s.to_json() if args.json else format_summary(s))
    return 0
