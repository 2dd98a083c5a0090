"""Whole commands as a user meets them: each in a fresh process, first with a clean
compilation cache (everything compiled), then with the cache the first run filled
(issue 23, parts 1 and 5), against the import floor measured in the same run (issue 30).

    python benchmarks/bench_startup.py [--recording FILE.txy] [--methods ...]
                                       [--rounds 1] [--docs DIR]

Rows: ``cassi jaw RECORDING --csv OUT --method M`` for every jaw method and ``cassi
animate RECORDING --out OUT.mp4`` (sound, every line, all five views at 640x480), each
timed from the process's start to its end (wall clock) with a clean cache folder and
then warm. The floor is a fresh process that only starts JAX and imports the toolkit
(:data:`FLOOR`), timed just before every warm run: a warm run is divided by its own floor
(the two ran under the same load), and a row shows its best round. Targets:
any jaw method warm in at most :data:`JAW_FLOOR_X` times the floor (issue 30), the MP4 in
at most 2x the recording's length from a clean cache and 1.5x warm. A miss is printed
with its size and where the warm time beyond the floor goes: the imports beyond the
floor's (one more warm run under ``python -X importtime``, by package) and the rest (the
command's own work: reading, loading the compiled kernels, computing, writing).

Python keeps its bytecode for the commands as in any installation (PYTHONDONTWRITEBYTECODE
is dropped for them: the checkout's ``__pycache__`` folders, which git ignores). The load
average is printed: on a shared machine every wall time is longer than on an idle one,
the ratios less so. With ``--docs DIR`` the table is written to ``DIR/bench_startup.md``.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: What every command pays before its own work: Python, JAX started, the toolkit imported.
FLOOR = "import jax, jax.numpy as jnp, cassi_fit; jnp.zeros(1).block_until_ready()"
JAW_FLOOR_X = 1.5
VIDEO_WARM_X, VIDEO_CLEAN_X = 1.5, 2.0


def _recording_default() -> Path | None:
    for base in (*ROOT.parents, Path("/work")):  # ../shared beside the checkout, or above
        candidate = base / "shared/data/xrmb_jw11/jw11_tp005.txy"
        if candidate.is_file():
            return candidate
    return None


def _cassi() -> list[str]:
    return [sys.executable, "-m", "cassi_fit.cli"]


def _env(cache: Path) -> dict[str, str]:
    env = {**os.environ, "CASSI_COMPILE_CACHE": str(cache), "JAX_PLATFORMS": "cpu"}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def _run(argv: list[str], cache: Path, cwd: Path) -> tuple[float, str]:
    """(wall seconds, stderr) of ``argv`` in a fresh process with the cache in ``cache``."""
    start = time.perf_counter()
    done = subprocess.run(argv, cwd=cwd, env=_env(cache), capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv[2:])} failed: {done.stderr.strip()[-500:]}")
    return wall, done.stderr


def timed(argv: list[str], cache: Path, cwd: Path) -> float:
    """Wall seconds of ``cassi ARGV`` in a fresh process with the cache in ``cache``."""
    return _run(_cassi() + argv, cache, cwd)[0]


def floor(work: Path) -> float:
    """Wall seconds of the floor (:data:`FLOOR`) in a fresh process."""
    return _run([sys.executable, "-c", FLOOR], work / "cache-floor", work)[0]


def imports_by_package(stderr: str) -> dict[str, float]:
    """Seconds of ``python -X importtime`` output, summed (self time) by top package."""
    out: dict[str, float] = defaultdict(float)
    for line in stderr.splitlines():
        m = re.match(r"import time:\s+(\d+) \|\s+\d+ \|\s*(\S+)", line)
        if m:
            out[m.group(2).split(".")[0]] += int(m.group(1)) / 1e6
    return out


def measure(label: str, argv: list[str], rounds: int, work: Path
            ) -> tuple[float, float, float, Path]:
    """(clean, warm, floor, that round's cache folder): the least clean time of ``rounds``,
    and the round whose warm time is the least multiple of its floor (timed just before
    it); a new clean cache for every round."""
    clean, warm, floors = [], [], []
    for k in range(rounds):
        cache = work / f"cache-{label.replace(' ', '-')}-{k}"
        clean.append(timed(argv, cache, work))
        floors.append(floor(work))
        warm.append(timed(argv, cache, work))
        print(f"{label:<28s} clean cache {clean[-1]:6.2f} s   warm {warm[-1]:6.2f} s   "
              f"floor {floors[-1]:5.2f} s", flush=True)
    best = min(range(rounds), key=lambda k: warm[k] / floors[k])
    return min(clean), warm[best], floors[best], work / f"cache-{label.replace(' ', '-')}-{best}"


def markdown(rows: list[tuple], misses: list[tuple], note: str) -> str:
    lines = [
        "<!-- written by `python benchmarks/bench_startup.py --docs docs/generated`; do not "
        "edit: `make bench` rewrites it -->",
        "# Commands from a fresh process: clean against warm compilation cache, against the "
        "import floor",
        "",
        f"One run of `benchmarks/bench_startup.py` ({note}). Each command in a new process, "
        "timed from its start to its end, first with an empty compilation cache folder, "
        "then again with the folder the first run filled. The floor: a new process that "
        f"only runs `{FLOOR}`, timed just before every warm run; warm / floor divides a "
        "warm run by its own floor (both under the same load), the best round of each row.",
        "",
        "| command | clean cache s | warm cache s | floor s | clean / warm | warm / floor | "
        "warm / recording | target | met |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, clean, warm, floor_s, length, target, met in rows:
        lines.append(f"| {label} | {clean:.2f} | {warm:.2f} | {floor_s:.2f} | {clean / warm:.2f} | "
                     f"{warm / floor_s:.2f} | {warm / length:.2f} | {target} | {met} |")
    if misses:
        lines += ["", "Where the warm time of each miss goes beyond the floor (one more warm "
                  "run under `python -X importtime`: the imports beyond the floor's, by "
                  "package; the rest is the command's own work):", "",
                  "| command | warm / floor | over the target s | imports over the floor's s "
                  "| largest | own work s |", "|---|---|---|---|---|---|"]
        lines += [f"| {label} | {x:.2f} | {over:.2f} | {more:.2f} | {named} | {own:.2f} |"
                  for label, x, over, more, named, own in misses]
    return "\n".join(lines) + "\n"


def why(argv: list[str], cache: Path, work: Path, base: dict[str, float], wall: float,
        floor_s: float) -> tuple[float, str, float]:
    """Where a warm command's time beyond the floor goes: ``(imports beyond the floor's s,
    the three largest packages, the command's own work s)`` (one more warm run under
    ``-X importtime``)."""
    _, stderr = _run([sys.executable, "-X", "importtime", "-m", "cassi_fit.cli", *argv],
                     cache, work)
    extra = {k: v - base.get(k, 0.0) for k, v in imports_by_package(stderr).items()}
    more = sum(extra.values())
    top = sorted(extra.items(), key=lambda kv: -kv[1])[:3]
    named = ", ".join(f"{k} {v:+.2f}" for k, v in top if v > 0.005) or "-"
    return more, named, wall - floor_s - more


def _jaw_rows(args, length: float, work: Path) -> list[tuple]:
    rows = []
    for method in args.methods:
        argv_ = ["jaw", str(args.recording), "--csv", str(work / "jaw.csv"), "--force",
                 "--method", method]
        clean, warm, floor_s, cache = measure(f"jaw {method}", argv_, args.rounds, work)
        rows.append((f"`cassi jaw --method {method}`", clean, warm, floor_s, length,
                     f"warm <= {JAW_FLOOR_X}x the floor", argv_, cache))
    return rows


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
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        floor(work)  # the checkout's bytecode written, as every later process finds it
        measured = _jaw_rows(args, length, work)
        if not args.no_video:
            argv_ = ["animate", str(args.recording), "--out", str(work / "talk.mp4"),
                     "--force", "--quiet"]
            clean, warm, floor_s, cache = measure("animate to MP4", argv_, args.rounds, work)
            measured.append(("`cassi animate --out talk.mp4` (sound, 5 views, 640x480)",
                             clean, warm, floor_s, length, None, argv_, cache))
        _, base = _run([sys.executable, "-X", "importtime", "-c", FLOOR], work / "cache-floor",
                       work)
        rows, misses = _judge(measured, imports_by_package(base), work)
    after = os.getloadavg()
    note = (f"{args.recording.name}: {track.n_frames} lines, {length:.2f} s (one recording "
            f"of one speaker); floor {min(m[3] for m in measured):.2f}-"
            f"{max(m[3] for m in measured):.2f} s; {os.cpu_count()} CPUs; load average "
            f"{load[0]:.1f} before, {after[0]:.1f} after (other processes slow every wall "
            f"time); best of {args.rounds} round(s)")
    text = markdown(rows, misses, note)
    print(text)
    if args.docs:
        from cassi_fit._io import atomic_write

        atomic_write(Path(args.docs) / "bench_startup.md", text, overwrite=True)
    return 0


def _judge(measured: list[tuple], base: dict[str, float], work: Path
           ) -> tuple[list[tuple], list[tuple]]:
    """The table's rows (each against its target) and, for every jaw row that misses, by
    how much and why (:func:`why`; printed as found)."""
    rows, misses = [], []
    for label, clean, warm, floor_s, length, target, argv_, cache in measured:
        if target is None:  # the MP4: against the recording's length
            met = ("yes" if warm <= VIDEO_WARM_X * length and clean <= VIDEO_CLEAN_X * length
                   else "NOT MET")
            target = f"warm <= {VIDEO_WARM_X}x, clean <= {VIDEO_CLEAN_X}x the recording"
        elif warm <= JAW_FLOOR_X * floor_s:
            met = "yes"
        else:
            over = warm - JAW_FLOOR_X * floor_s
            met = f"NOT MET (+{over:.2f} s)"
            more, named, own = why(argv_, cache, work, base, warm, floor_s)
            misses.append((label, warm / floor_s, over, more, named, own))
            print(f"{label}: {warm / floor_s:.2f}x the floor, misses {JAW_FLOOR_X}x by "
                  f"{over:.2f} s: imports {more:+.2f} s over the floor's ({named}), the "
                  f"command's own work {own:.2f} s", flush=True)
        rows.append((label, clean, warm, floor_s, length, target, met))
    return rows, misses


if __name__ == "__main__":
    sys.exit(main())
