"""Whole commands as a user meets them: each in a fresh process, first with a clean
compilation cache (everything compiled), then with the cache the first run filled
(issue 23, parts 1 and 5).

    python benchmarks/bench_startup.py [--recording FILE.txy] [--methods ...]
                                       [--rounds 1] [--docs DIR]

Rows: ``cassi jaw RECORDING --csv OUT --method M`` for every jaw method and ``cassi
animate RECORDING --out OUT.mp4`` (sound, every line, all five views at 640x480), each
timed from the process's start to its end (wall clock) with a clean cache folder and
then warm. Ratios measured in this one run: clean / warm, and each time against the
recording's length (targets: the MP4 in at most 2x the recording's length from a clean
cache and 1.5x warm; any jaw method in at most 1.5 s warm). The load average is printed:
on a shared machine every wall time is longer than on an idle one, the ratios less so.
With ``--docs DIR`` the table is written to ``DIR/bench_startup.md``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
JAW_TARGET_S = 1.5
VIDEO_WARM_X, VIDEO_CLEAN_X = 1.5, 2.0


def _recording_default() -> Path | None:
    for base in (*ROOT.parents, Path("/work")):  # ../shared beside the checkout, or above
        candidate = base / "shared/data/xrmb_jw11/jw11_tp005.txy"
        if candidate.is_file():
            return candidate
    return None


def _cassi() -> list[str]:
    return [sys.executable, "-m", "cassi_fit.cli"]


def timed(argv: list[str], cache: Path, cwd: Path) -> float:
    """Wall seconds of ``cassi ARGV`` in a fresh process with the cache in ``cache``."""
    env = {**os.environ, "CASSI_COMPILE_CACHE": str(cache), "JAX_PLATFORMS": "cpu"}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    start = time.perf_counter()
    done = subprocess.run(_cassi() + argv, cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"cassi {' '.join(argv)} failed: {done.stderr.strip()[-500:]}")
    return wall


def measure(label: str, argv: list[str], rounds: int, work: Path) -> tuple[float, float]:
    """(clean, warm): the best of ``rounds`` of each; a new clean cache for every round."""
    clean, warm = [], []
    for k in range(rounds):
        cache = work / f"cache-{label.replace(' ', '-')}-{k}"
        clean.append(timed(argv, cache, work))
        warm.append(timed(argv, cache, work))
        print(f"{label:<28s} clean cache {clean[-1]:6.2f} s   warm {warm[-1]:6.2f} s",
              flush=True)
    return min(clean), min(warm)


def markdown(rows: list[tuple], note: str) -> str:
    lines = [
        "<!-- written by `python benchmarks/bench_startup.py --docs docs/generated`; do not "
        "edit: `make bench` rewrites it -->",
        "# Commands from a fresh process: clean against warm compilation cache",
        "",
        f"One run of `benchmarks/bench_startup.py` ({note}). Each command in a new process, "
        "timed from its start to its end, first with an empty compilation cache folder, "
        "then again with the folder the first run filled.",
        "",
        "| command | clean cache s | warm cache s | clean / warm | warm / recording | "
        "target | met |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, clean, warm, length, target, met in rows:
        lines.append(f"| {label} | {clean:.2f} | {warm:.2f} | {clean / warm:.2f} | "
                     f"{warm / length:.2f} | {target} | {met} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=_recording_default())
    parser.add_argument("--methods", nargs="+",
                        default=["closed-form", "frame-fit", "fixed-pivot", "smooth-pivot"])
    parser.add_argument("--no-video", action="store_true", help="only the jaw rows")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--docs", metavar="DIR", help="also write DIR/bench_startup.md")
    args = parser.parse_args(argv)
    if args.recording is None or not args.recording.is_file():
        raise SystemExit("no recording: give --recording FILE.txy (the real JW11 recording "
                         "is used when ../shared/data/xrmb_jw11/ is there)")
    from cassi_fit.txy import read_txy

    track = read_txy(args.recording)
    length = float(track.times[-1] - track.times[0])
    load = os.getloadavg()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        for method in args.methods:
            argv_ = ["jaw", str(args.recording), "--csv", str(work / "jaw.csv"), "--force",
                     "--method", method]
            clean, warm = measure(f"jaw {method}", argv_, args.rounds, work)
            met = "yes" if warm <= JAW_TARGET_S else "NOT MET"
            rows.append((f"`cassi jaw --method {method}`", clean, warm, length,
                         f"warm <= {JAW_TARGET_S} s", met))
        if not args.no_video:
            argv_ = ["animate", str(args.recording), "--out", str(work / "talk.mp4"),
                     "--force", "--quiet"]
            clean, warm = measure("animate to MP4", argv_, args.rounds, work)
            met = ("yes" if warm <= VIDEO_WARM_X * length and clean <= VIDEO_CLEAN_X * length
                   else "NOT MET")
            rows.append(("`cassi animate --out talk.mp4` (sound, 5 views, 640x480)", clean,
                         warm, length, f"warm <= {VIDEO_WARM_X}x, clean <= {VIDEO_CLEAN_X}x "
                         "the recording", met))
    after = os.getloadavg()
    note = (f"{args.recording.name}: {track.n_frames} lines, {length:.2f} s (one recording "
            f"of one speaker); {os.cpu_count()} CPUs; load average {load[0]:.1f} before, "
            f"{after[0]:.1f} after (other processes slow every wall time); best of "
            f"{args.rounds} round(s)")
    text = markdown(rows, note)
    print(text)
    if args.docs:
        from cassi_fit._io import atomic_write

        atomic_write(Path(args.docs) / "bench_startup.md", text, overwrite=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
