"""Ratios that hold on any machine (issue 30): a video's real-time factor beside a fixed
reference workload, the whole command against its render floor, parallel against serial
drawing, warm against clean compilation cache; every figure measured in this one run.

    python benchmarks/bench_realtime.py [--recording FILE.txy] [--jobs 2] [--docs DIR]

On the real JW11 recording (``../shared/data/xrmb_jw11/jw11_tp005.txy``, 5.0 s; the
script stops with a clear line if it is absent), with today's defaults (sound, all five
views at 640x480, improved mode):

- ``cassi animate`` to MP4 in a fresh process at 60 fps (the default) and at ``--fps
  native`` (one frame per data line), with a warm compilation cache, and at 60 fps with a
  clean one: wall time over the recording's length (the real-time factor);
- a fixed reference workload (a pure-Python loop) timed here: divide any seconds below by
  it to compare machines;
- the render floor: the same video frames drawn by the bare OpenGL pass of the same scene
  at the same size (``Renderer.render_gl``: vertex upload, draw, read-back; no caption,
  no midsagittal view, no encoding, no start-up), in this process after a warm-up; its
  draw calls and triangles a frame; and the same with the scene before parts hidden in a
  view were left out of it (issue 30 item 4), so that the cut's gain shows;
- the phases of a warm 60 fps video in one fresh process (start-up, initialize, animate,
  video) and a bare ``python -c "import jax, ...; jnp.zeros(1)"`` beside them; and the
  interpreter's exit after a warm ``cassi animate`` (after its last exit handler: none of
  those phases, part of the command's time);
- a MOCHA-TIMIT-like recording at 500 Hz (the toolkit's synthetic EMA corpus in EST
  ASCII, one jaw and three tongue sensors, with its sound; no real MOCHA file is at hand):
  ``cassi animate`` to MP4 at 60 fps with a warm cache, its real-time factor;
- drawing the 60 fps frames whole (caption, midsagittal view) in this process against
  ``--jobs`` drawing processes (``render.FramePool``: this one and ``--jobs`` - 1
  workers, their start-up included), and the whole command with ``--jobs`` against one
  process. This process uses the default llvmpipe threads (one per core), each worker
  its share.

The load average is printed: on a shared machine every wall time is longer, the ratios
less so. With ``--docs DIR`` the table goes to ``DIR/bench_realtime.md``.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FLOOR_X, PARALLEL_X = 1.3, 1.7


def _recording_default() -> Path | None:
    for base in (*ROOT.parents, Path("/work")):  # ../shared beside the checkout, or above
        candidate = base / "shared/data/xrmb_jw11/jw11_tp005.txy"
        if candidate.is_file():
            return candidate
    return None


def reference_workload() -> float:
    """Seconds of a fixed pure-Python loop (best of 3): the machine's yardstick."""
    best = float("inf")
    for _ in range(3):
        start = time.perf_counter()
        total = 0
        for i in range(2_000_000):
            total += (i * i) % 7
        best = min(best, time.perf_counter() - start)
    return best


def animate_wall(recording: Path, out: Path, cache: Path, *extra: str) -> float:
    """Wall seconds of ``cassi animate RECORDING --out OUT`` in a fresh process."""
    env = {**os.environ, "CASSI_COMPILE_CACHE": str(cache), "JAX_PLATFORMS": "cpu"}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    argv = [sys.executable, "-m", "cassi_fit.cli", "animate", str(recording), "--out",
            str(out), "--force", "--quiet", *extra]
    start = time.perf_counter()
    done = subprocess.run(argv, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"cassi animate {' '.join(extra)} failed: {done.stderr[-500:]}")
    print(f"  cassi animate {' '.join(extra) or '(defaults)'}: {wall:.2f} s", flush=True)
    return wall


#: A child that runs ``cassi animate`` as ``python -m cassi_fit.cli`` does and says, on
#: stderr, the time its last exit handler ran: what follows is the interpreter's own exit.
_MARKED_EXIT = """import atexit, os, runpy, sys, time
atexit.register(lambda: os.write(2, f"@@exit {time.time()!r}\\n".encode()))  # runs last
sys.argv = ["cassi", *sys.argv[1:]]
runpy.run_module("cassi_fit.cli", run_name="__main__")
"""


def exit_wall(recording: Path, out: Path, cache: Path) -> tuple[float, float]:
    """``(whole, exit)`` wall seconds of a warm ``cassi animate`` in a fresh process: the
    whole command, and its interpreter's exit (from the last exit handler to the end of
    the process: module teardown, the last garbage collections, the libraries' own
    clean-up), outside every phase of :func:`phases`."""
    env = {**os.environ, "CASSI_COMPILE_CACHE": str(cache), "JAX_PLATFORMS": "cpu"}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    argv = [sys.executable, "-c", _MARKED_EXIT, "animate", str(recording), "--out", str(out),
            "--force", "--quiet"]
    start = time.perf_counter()
    done = subprocess.run(argv, env=env, capture_output=True, text=True)
    end, wall = time.time(), time.perf_counter() - start
    marks = [ln for ln in done.stderr.splitlines() if ln.startswith("@@exit ")]
    if done.returncode != 0 or not marks:
        raise SystemExit(f"cassi animate (exit marked) failed: {done.stderr[-500:]}")
    seconds = end - float(marks[-1].split()[1])
    print(f"  cassi animate: {wall:.2f} s, its interpreter's exit {seconds:.2f} s", flush=True)
    return wall, seconds


def mocha_like(folder: Path) -> Path:
    """The synthetic EMA corpus's sentence (``synth.SENTENCE_TASK``) of one subject as a
    MOCHA-TIMIT-like file: EST ASCII at 500 Hz, MOCHA's sensors, its sound beside it."""
    import warnings

    from cassi_fit import synth
    from cassi_fit.ema.synthetic import write_ema_corpus

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        root = write_ema_corpus(folder / "mocha_like", format="est-ascii", n_subjects=1,
                                tasks=synth.SENTENCE_TASK, seed=3, sensors="mocha")
    return next(p for p in root.rglob(f"{synth.SENTENCE_TASK}.ema"))


def phases(recording: Path, out: Path) -> None:
    """The child of :func:`phases_wall`: one warm 60 fps video in this fresh process, its
    phases' wall seconds as JSON on stdout."""
    import json
    import warnings

    start = time.perf_counter()
    times = {}

    def mark(name: str) -> None:
        times[name] = time.perf_counter() - start - sum(times.values())

    import jax.numpy as jnp

    import cassi_fit  # noqa: F401

    jnp.zeros(1).block_until_ready()
    from cassi_fit import recording_video as rv
    from cassi_fit.corpus._process import default_compile_cache, use_compile_cache
    from cassi_fit.dataset import load_recording
    from cassi_fit.initialize import initialize
    from cassi_fit.pipeline import RecordingRun

    use_compile_cache(default_compile_cache())
    mark("start-up (Python, JAX, imports)")
    warnings.simplefilter("ignore")
    from cassi_fit.render import prepare_gl

    prepare_gl()  # as cassi animate does: OpenGL readied while it fits and animates
    loaded = load_recording(recording)
    state = initialize(loaded)
    mark("initialize (load, fit the subject)")
    from cassi_fit.animate import animate

    animation = animate(state, loaded)
    animation.vertices.block_until_ready()
    mark("animate (every line's geometry)")
    rv.write_recording_video(out, RecordingRun(loaded, state.spec, state, animation),
                             progress=False, overwrite=True)
    mark("video (renderer, drawing, encoding, sound)")
    print(json.dumps(times))


def phases_wall(recording: Path, out: Path, cache: Path) -> dict[str, float]:
    """Phases of a warm 60 fps video in a fresh process, and the bare start-up of
    ``python -c "import jax, jax.numpy as jnp, cassi_fit; jnp.zeros(1)..."``."""
    import json

    env = {**os.environ, "CASSI_COMPILE_CACHE": str(cache), "JAX_PLATFORMS": "cpu"}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    done = subprocess.run([sys.executable, __file__, "--phases-of", str(recording), "--out",
                           str(out)], env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"the phases run failed: {done.stderr[-500:]}")
    times = json.loads(done.stdout.strip().splitlines()[-1])
    start = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import jax, jax.numpy as jnp, cassi_fit; "
                    "jnp.zeros(1).block_until_ready()"], env=env, check=True)
    times["bare"] = time.perf_counter() - start
    print(f"  phases: {times}", flush=True)
    return times


def _floors(renderers, vertices, index, chunk: int = 10) -> list[float]:
    """Seconds of the bare OpenGL pass (``render_gl``) of the frames ``index`` by each of
    ``renderers``, after a warm-up; in turns of ``chunk`` frames, so that a change in the
    machine's load during the run weighs on each alike."""
    for renderer in renderers:
        for k in index[:5]:
            renderer.render_gl(vertices[k])
    seconds = [0.0] * len(renderers)
    for at in range(0, len(index), chunk):
        for i, renderer in enumerate(renderers):
            start = time.perf_counter()
            for k in index[at:at + chunk]:
                renderer.render_gl(vertices[k])
            seconds[i] += time.perf_counter() - start
    return seconds


@contextlib.contextmanager
def _previous_scene():
    """Renderers made within draw the scene before issue 30's item 4: palate, pharynx and
    the mouth's walls also in the side view (hidden there by the cheeks and the neck)."""
    from cassi_fit.render import _pieces

    side = _pieces._SHOWN["side"]
    _pieces._SHOWN["side"] = side | {"palate", "pharynx", _pieces._MOUTH_WALL}
    try:
        yield
    finally:
        _pieces._SHOWN["side"] = side


def in_process(recording: Path, jobs: int) -> dict:
    """The render floor, serial and parallel drawing of the 60 fps frames, here."""
    import numpy as np

    from cassi_fit import recording_video as rv
    from cassi_fit.dataset import load_recording
    from cassi_fit.options import VIEWS
    from cassi_fit.pipeline import run_recording
    from cassi_fit.render import FramePool, Renderer

    run = run_recording(load_recording(recording))
    schedule = rv.video_frames(run.animation, 60)
    vertices = np.asarray(run.animation.vertices)
    traces = rv.subject_traces(run.recording, run.state.scale)
    setup = {"size": (640, 480), "views": VIEWS, "grid": True, "traces": traces}
    options = {"subject": run.recording.subject, "task": run.recording.task,
               "frames": schedule}
    out = {"frames": float(len(schedule.index))}
    with Renderer(run.state.model, **setup) as renderer:
        with _previous_scene():
            before = Renderer(run.state.model, **setup)
        with before:
            out["floor"], out["floor_before"] = _floors([renderer, before], vertices,
                                                        schedule.index)
            out["drawn"], out["drawn_before"] = renderer.drawn(), before.drawn()
        start = time.perf_counter()
        for _ in rv.animation_frames(run.animation, renderer, progress=False, **options):
            pass
        out["serial"] = time.perf_counter() - start
    start = time.perf_counter()
    with FramePool(run.state.model, jobs=jobs, **setup) as pool:
        work = rv.frame_work(run.animation, section=True, **options)
        for _ in pool.draw(work):
            pass
        out["threads"] = float(pool.threads)
    out["parallel"] = time.perf_counter() - start
    print(f"  in this process: floor {out['floor']:.2f} s, serial {out['serial']:.2f} s, "
          f"{jobs} workers {out['parallel']:.2f} s for {len(schedule.index)} frames",
          flush=True)
    return out


def _length(path: Path) -> tuple[float, int]:
    """(seconds, data lines) of an articulograph file."""
    import warnings

    from cassi_fit.dataset import load_recording

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        track = load_recording(path).track
    return float(track.length_s), int(track.n_frames)


def table(m: dict, length: float, jobs: int) -> list[tuple[str, str, str, str, str]]:
    """Rows: (what, seconds, ratio, target, met)."""
    def met(ok: bool) -> str:
        return "yes" if ok else "NOT MET"

    phases = {k: v for k, v in m["phases"].items() if k != "bare"}
    total = sum(phases.values())
    rtf60, rtfn = m["warm60"] / length, m["native"] / length
    floor_x = m["warm60"] / m["floor"]
    draw_x = m["serial"] / m["parallel"]
    cmd_x = m["warm60"] / m["jobs"]
    (calls, tris), (calls0, tris0) = m["drawn"], m["drawn_before"]
    bound = m["floor"] + m["phases"]["bare"]
    return [
        ("reference workload (pure-Python loop)", f"{m['ref']:.3f}", "1 (yardstick)", "", ""),
        ("`cassi animate` JW11 to MP4, 60 fps, warm cache", f"{m['warm60']:.2f}",
         f"{rtf60:.2f}x real time; {m['warm60'] / m['ref']:.0f}x reference",
         "< 1x real time", met(rtf60 < 1)),
        ("`cassi animate` JW11 to MP4, --fps native, warm cache", f"{m['native']:.2f}",
         f"{rtfn:.2f}x real time; native / 60 fps {m['native'] / m['warm60']:.2f}", "", ""),
        ("`cassi animate` JW11 to MP4, 60 fps, clean cache", f"{m['clean60']:.2f}",
         f"clean / warm {m['clean60'] / m['warm60']:.2f}", "", ""),
        (f"`cassi animate` MOCHA-TIMIT-like EST ASCII at 500 Hz (synthetic; "
         f"{m['mocha_lines']} lines, {m['mocha_s']:.2f} s, sound) to MP4, 60 fps, warm cache",
         f"{m['mocha']:.2f}", f"{m['mocha'] / m['mocha_s']:.2f}x real time",
         "< 1x real time", met(m['mocha'] < m['mocha_s'])),
        (f"render floor: the {int(m['frames'])} frames' OpenGL pass alone ({calls} draw "
         f"calls, {tris} triangles a frame)", f"{m['floor']:.2f}",
         f"whole command / floor {floor_x:.2f}", f"<= {FLOOR_X}x", met(floor_x <= FLOOR_X)),
        (f"the same, the previous scene ({calls0} draw calls, {tris0} triangles: palate, "
         "pharynx and mouth walls also in the side view)", f"{m['floor_before']:.2f}",
         f"previous / current scene {m['floor_before'] / m['floor']:.2f}", "", ""),
        ("drawing the 60 fps frames whole, one process", f"{m['serial']:.2f}",
         f"serial / floor {m['serial'] / m['floor']:.2f}", "", ""),
        (f"the same, {jobs} drawing processes (this one and {jobs - 1} worker(s), start-up "
         f"included; LP_NUM_THREADS {int(m['threads'])} each worker)", f"{m['parallel']:.2f}",
         f"serial / parallel {draw_x:.2f}",
         f">= {PARALLEL_X}x", met(draw_x >= PARALLEL_X)),
        (f"`cassi animate` JW11, 60 fps, warm, --jobs {jobs}", f"{m['jobs']:.2f}",
         f"--jobs 1 / --jobs {jobs}: {cmd_x:.2f}", "", ""),
        ("the interpreter's exit after a warm 60 fps `cassi animate` (after its last exit "
         "handler: module teardown, garbage collection)", f"{m['exit']:.2f}",
         f"{m['exit'] / m['marked']:.0%} of that command's {m['marked']:.1f} s", "", ""),
        ("`python -c \"import jax, jax.numpy as jnp, cassi_fit; jnp.zeros(1)...\"`",
         f"{m['phases']['bare']:.2f}", "1 (a process's floor)", "", ""),
        ("the least a warm 60 fps `cassi animate` of JW11 could take here: the render floor "
         "plus a process's floor (no fitting, no encoding)", f"{bound:.2f}",
         f"{bound / length:.2f}x real time; the real-time target leaves "
         f"{length - bound:.2f} s for all else", "", ""),
    ] + [(f"warm 60 fps video in one fresh process: {name}", f"{value:.2f}",
          f"{value / total:.0%} of that process's {total:.1f} s", "", "")
         for name, value in phases.items()]


def markdown(rows: list[tuple], note: str) -> str:
    lines = [
        "<!-- written by `python benchmarks/bench_realtime.py --docs docs/generated`; do not "
        "edit -->",
        "# Real time, render floor, parallel drawing, compilation cache (issue 30)",
        "",
        f"One run of `benchmarks/bench_realtime.py` ({note}). Every ratio is of two times "
        "measured in this run on this machine; the seconds are this machine's (compare "
        "machines by the reference workload's time).",
        "",
        "| measurement | seconds | ratio | target | met |",
        "|---|---|---|---|---|",
    ]
    lines += [f"| {' | '.join(row)} |" for row in rows]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=_recording_default())
    parser.add_argument("--jobs", type=int, default=2, help="drawing processes (default 2)")
    parser.add_argument("--docs", metavar="DIR", help="also write DIR/bench_realtime.md")
    parser.add_argument("--phases-of", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.phases_of is not None:  # the child of phases_wall
        phases(args.phases_of, args.out)
        return 0
    if args.recording is None or not args.recording.is_file():
        print("SKIPPED: the real JW11 recording is absent (../shared/data/xrmb_jw11/); give "
              "--recording FILE.txy", file=sys.stderr)
        return 0
    from cassi_fit.render import egl_device, ensure_headless_gl
    from cassi_fit.txy import read_txy

    track = read_txy(args.recording)
    length = track.length_s
    load = os.getloadavg()
    m = {"ref": reference_workload()}
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        cache, out = work / "cache", work / "talk.mp4"
        m["clean60"] = animate_wall(args.recording, out, cache)
        m["warm60"] = animate_wall(args.recording, out, cache)
        m["native"] = animate_wall(args.recording, out, cache, "--fps", "native")
        m["jobs"] = animate_wall(args.recording, out, cache, "--jobs", str(args.jobs))
        m["marked"], m["exit"] = exit_wall(args.recording, out, cache)
        m["phases"] = phases_wall(args.recording, out, cache)
        mocha = mocha_like(work)
        animate_wall(mocha, out, cache)  # its shapes compiled once
        m["mocha"] = animate_wall(mocha, out, cache)
        m["mocha_s"], m["mocha_lines"] = _length(mocha)
    m.update(in_process(args.recording, args.jobs))
    after = os.getloadavg()
    ensure_headless_gl()
    device = egl_device() or {}
    note = (f"{args.recording.name}: {track.n_frames} lines, {length:.2f} s (one recording "
            f"of one speaker); {os.cpu_count()} CPUs, drawn by "
            f"{device.get('renderer', 'an unknown OpenGL renderer')}; load average "
            f"{load[0]:.1f} before, {after[0]:.1f} after (other processes slow every wall "
            "time)")
    text = markdown(table(m, length, args.jobs), note)
    print(text)
    if args.docs:
        from cassi_fit._io import atomic_write

        atomic_write(Path(args.docs) / "bench_realtime.md", text, overwrite=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
