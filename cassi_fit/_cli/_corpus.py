"""Options shared by the corpus forms of the commands (``cassi jaw DATASET``, ``cassi
calibrate``, ``cassi evaluate``, ``cassi animate DATASET``): where the recordings run,
resuming, and the end-of-run failure summary. The runner is ``cassi_fit.corpus``."""

from __future__ import annotations

import argparse
import sys


def add_run_arguments(parser: argparse.ArgumentParser, *, force: bool = True) -> None:
    """``--jobs``, ``--scheduler``, ``--resume`` (and ``--force`` unless the command has
    its own)."""
    parser.add_argument("--jobs", type=int, metavar="N",
                        help="recordings run in N local worker processes (default: all "
                        "cores; 1: in this process)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="send the recordings to a running dask.distributed cluster "
                        "(e.g. tcp://host:8786) instead of local processes (needs the "
                        "'corpus' extra)")
    parser.add_argument("--scheduler-timeout", type=float, metavar="SECONDS",
                        help="time allowed to reach the --scheduler (default: "
                        "$CASSI_SCHEDULER_TIMEOUT or 10 s)")
    parser.add_argument("--resume", action="store_true",
                        help="skip recordings whose outputs an earlier run of the same "
                        "settings completed (checked by their markers), run the rest")
    if force:
        parser.add_argument("--force", action="store_true",
                            help="replace existing outputs (and rerun every recording)")


def run_options(args: argparse.Namespace) -> dict:
    """``corpus.run_corpus`` keywords from the parsed options."""
    from cassi_fit.errors import CassiError

    if args.jobs is not None and args.jobs < 1:
        raise CassiError(f"--jobs must be at least 1, got {args.jobs}")
    if args.jobs is not None and args.scheduler:
        raise CassiError("--jobs and --scheduler exclude each other (the cluster decides "
                         "its workers)")
    timeout = getattr(args, "scheduler_timeout", None)
    if args.scheduler is not None:  # a malformed address fails before any work
        from cassi_fit.corpus import parse_scheduler_address, scheduler_timeout

        parse_scheduler_address(args.scheduler)
        scheduler_timeout(timeout)
    elif timeout is not None:
        raise CassiError("--scheduler-timeout is for --scheduler")
    return {"jobs": args.jobs, "scheduler": args.scheduler, "scheduler_timeout": timeout,
            "resume": args.resume, "overwrite": args.force,
            "progress": not getattr(args, "quiet", False)}


def finish(run) -> int:
    """Print what was resumed and the failures (stderr); 1 if any recording failed."""
    if run.resumed:
        print(f"resumed: {run.resumed} of {len(run.results)} already done", file=sys.stderr)
    summary = run.failure_summary()
    if summary:
        print(summary, file=sys.stderr)
        return 1
    return 0
