"""Benchmark: every data line of a 5-second recording rendered to MP4 (issue 5, section 5).

Targets on 2 CPU cores: the geometry of all ~730 frames in one jitted call in under 0.2 s
after compilation; the whole job (initialize, animate, render the 640x480 2x2 grid of every
frame, encode the MP4) in under 20 s. Issue 13: the same job with the midsagittal view
added (the 3x2 grid of five views) at most 20 % slower; both grids are measured in the
one run (same recording, same compiled functions) and their ratio written. Prints the
numbers; run with

    .venv/bin/python benchmarks/bench_animation.py [--size 640x480] [--seconds 5] [--out FILE]
                                                   [--docs DIR]

Issue 23: rendering and encoding in step. ``cassi animate`` draws each frame in the main
thread while a writer thread hands the previous ones to ffmpeg (a bounded queue); the same
five-view job is also run the old way (the main thread writes each frame and waits) and
with each frame's 2D drawing in a helper thread too, and the ratios written. Whole commands
from a fresh process with a clean and a warm compilation cache are in ``bench_startup.py``.

With ``--docs DIR`` the printed table is also written to ``DIR/bench_animation.md``
(``make bench`` passes ``--docs docs/generated``; docs/PIPELINE.md and the README quote it
byte for byte).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

os.environ.setdefault("JAX_PLATFORMS", "cpu")


def synthetic_recording(seconds: float, seed: int = 7):
    """A ``Recording`` held in memory: one synthetic subject saying a sentence."""
    import numpy as np

    from cassi_fit import synth
    from cassi_fit.dataset import Recording

    anatomy = synth.make_subject("BENCH", np.random.default_rng(seed))
    track, _ = synth.synth_recording(anatomy, synth.SENTENCE_TASK, seed=seed, duration_s=seconds)
    return Recording(
        subject="BENCH",
        task=synth.SENTENCE_TASK,
        track=track,
        palate=anatomy.palate,
        pharynx=anatomy.pharynx,
        head=anatomy.head,
        head_is_default=False,
        audio=None,
        path=Path("bench.txy"),
    )


def _children_cpu() -> float:
    """CPU seconds used so far by finished child processes (ffmpeg)."""
    import resource

    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _timed(label, fn, results):
    start = time.perf_counter()
    value = fn()
    results[label] = time.perf_counter() - start
    print(f"{label:<34s} {results[label]:8.3f} s", flush=True)
    return value


TARGETS = {"geometry, all frames, compiled": "< 0.2 s", "total wall time": "< 20 s"}
FIVE = "five views (with midsagittal)"
ONE_STEP = "five views, one step (the old path)"
HELPER = "five views, 2D drawing in a helper thread"
CPU = "CPU time of render + encode (this process and ffmpeg)"


class OneStep:
    """A renderer seen through ``render`` alone: ``recording_video.animation_frames`` then draws
    each frame whole in the main thread, as before issue 23."""

    def __init__(self, renderer):
        self.views = renderer.views
        self.render = renderer.render


def helper_path(out, animation, renderer) -> None:
    """The MP4 with each frame's 2D drawing in a helper thread (``helper_thread=True``) and
    the writer thread."""
    from cassi_fit import recording_video, video

    frames = recording_video.animation_frames(animation, renderer, subject="BENCH", task="sentence",
                                    progress=False, helper_thread=True)
    video.write_video(out, frames, video.frame_rate(animation.frame_step_s), overwrite=True)


def old_path(out, animation, renderer) -> None:
    """The MP4 as before issue 23: each frame drawn whole in the main thread, which then
    writes it to ffmpeg and waits (no helper thread, no writer thread)."""
    from cassi_fit import recording_video, video

    frames = recording_video.animation_frames(animation, OneStep(renderer), subject="BENCH",
                                    task="sentence", progress=False)
    writer = video.VideoWriter(out, video.frame_rate(animation.frame_step_s),
                               overwrite=True, writer_thread=False)
    with writer:
        for frame in frames:
            writer.append(frame)
RATIO_TARGET = 1.2


def markdown(results: dict, note: str, ratios: dict | None = None) -> str:
    """``bench_animation.md``: the first line names the command, then stage | time | target."""
    lines = [
        "<!-- written by `python benchmarks/bench_animation.py --docs docs/generated`; do not "
        "edit: `make bench` rewrites it -->",
        "# Animation speed: a recording to MP4",
        "",
        f"One run of `benchmarks/bench_animation.py` ({note}); the first initialize and "
        "animate in a process include JAX compilation; geometry: best of three, compiled.",
        "",
        "| stage | time | target |",
        "|---|---|---|",
    ]
    lines += [f"| {k} | {v:.3f} s | {TARGETS.get(k, '')} |" for k, v in results.items()]
    if ratios:
        lines += [
            "",
            "The same job with the midsagittal view in the grid (3x2, five views) against the "
            "2x2 grid of four, as the ratio of the two times (issue 13's limit: 20 % slower); "
            "the CPU time (of this process's threads, OpenGL's included, and of ffmpeg) "
            "depends little on the other processes, the wall times much:",
            "",
            "| five views / four views | ratio | target |",
            "|---|---|---|",
        ]
        lines += [f"| {k} | {v:.2f} | {'<= 1.20' if k == 'total wall time' else ''} |"
                  for k, v in ratios.items() if k not in (ONE_STEP, HELPER)]  # fmt: skip
    if ratios and ONE_STEP in ratios:
        lines += [
            "",
            "Rendering and encoding in step (issue 23): the five-view job as `cassi animate` "
            "runs it (each frame drawn whole in the main thread, handed to ffmpeg by a writer "
            "thread, so drawing and encoding overlap) against the old path (the main thread "
            "writes each frame to ffmpeg and waits) and against each frame's 2D drawing "
            "(midsagittal view, caption) in a helper thread as well, as ratios of the "
            "render + encode times to the default's in this run, each the best of the "
            "rounds (the frames are the same bytes, tests/test_render_pipeline.py; all three "
            "do the same CPU work, so a ratio above 1 is overlap gained, and it depends on "
            "the free cores):",
            "",
            "| path / default path (five views, render + encode MP4) | ratio |",
            "|---|---|",
            f"| old path (no writer thread) | {ratios[ONE_STEP]:.2f} |",
            f"| 2D drawing in a helper thread too | {ratios[HELPER]:.2f} |",
        ]
    return "\n".join(lines) + "\n"


def _arguments(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="640x480")
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--out", help="keep the MP4 here (default: a temporary folder)")
    parser.add_argument("--docs", metavar="DIR", help="also write DIR/bench_animation.md")
    parser.add_argument("--rounds", type=int, default=2,
                        help="render each grid this many times, alternating; best kept")
    return parser.parse_args(argv)


def _common(seconds: float, results: dict) -> SimpleNamespace:
    """What both grids share, timed into ``results``: initialize, animate, the geometry
    of every frame (compiled: best of three) and OpenGL's start-up; ``common`` their wall
    time."""
    import jax

    from cassi_fit import recording_video
    from cassi_fit.animate import animate
    from cassi_fit.face_model import load_model
    from cassi_fit.frames import geometry
    from cassi_fit.initialize import initialize
    from cassi_fit.render import Renderer

    recording = synthetic_recording(seconds)
    model = load_model()
    wall = time.perf_counter()
    state = _timed("initialize", lambda: initialize(recording, model), results)
    animation = _timed("animate (incl. compilation)", lambda: animate(state, recording), results)
    m = animation.n_frames
    for _ in range(2):  # geometry alone, compiled: best of three
        jax.block_until_ready(geometry(state, animation.params))
    runs = []
    for _ in range(3):
        start = time.perf_counter()
        jax.block_until_ready(geometry(state, animation.params))
        runs.append(time.perf_counter() - start)
    results["geometry, all frames, compiled"] = min(runs)
    print(f"{'geometry, all frames, compiled':<34s} {min(runs):8.3f} s  ({m} frames)")
    # OpenGL's start-up (the first context of the process) alone, so that neither grid's
    # set-up carries it; it is counted in both totals.
    _timed("OpenGL start-up", lambda: Renderer(model, size=(16, 16), views=("front",)).close(),
           results)  # fmt: skip
    return SimpleNamespace(state=state, animation=animation, common=time.perf_counter() - wall,
                           traces=recording_video.subject_traces(recording, state.scale))


def _grids(args, run: SimpleNamespace, results: dict, cpus: dict) -> tuple[int, int]:
    """Every grid rendered ``args.rounds`` times, alternating (so that a burst of load hits
    all alike), each row kept as its best; the frames in the four- and five-view MP4s."""
    import numpy as np

    from cassi_fit import recording_video, video
    from cassi_fit.render import PAPER_VIEWS, VIEWS, Renderer

    width, height = (int(v) for v in args.size.split("x"))

    def job(views, label, out, path=None):
        """Set-up and render + encode of one grid; each kept as its best over the rounds."""
        best = {}
        renderer = _timed(f"renderer set-up{label}", lambda: Renderer(
            run.state.model, size=(width, height), views=views, traces=run.traces), best)
        cpu = time.process_time() + _children_cpu()
        _timed(
            f"render + encode MP4{label}",
            (lambda: path(out, run.animation, renderer)) if path else lambda: (
                recording_video.write_animation(out, run.animation, renderer, subject="BENCH",
                                      task="sentence", progress=False, overwrite=True)),
            best,
        )  # fmt: skip
        cpus[label] = min(cpus.get(label, np.inf), time.process_time() + _children_cpu() - cpu)
        renderer.close()
        for key, value in best.items():
            results[key] = min(results.get(key, value), value)
        return video.count_frames(out)

    with tempfile.TemporaryDirectory() as folder:
        out = Path(args.out) if args.out else Path(folder) / "bench.mp4"
        for _ in range(args.rounds):
            frames = job(PAPER_VIEWS, "", out)
            frames5 = job(VIEWS, f", {FIVE}", out.with_name(out.stem + "_five.mp4"))
            job(VIEWS, f", {ONE_STEP}", out.with_name(out.stem + "_one.mp4"), old_path)
            job(VIEWS, f", {HELPER}", out.with_name(out.stem + "_helper.mp4"), helper_path)
    return frames, frames5


def _ratios(results: dict, cpus: dict, common: float) -> dict:
    """The totals (into ``results``) and the ratios between the grids; the one-step and
    helper-thread rows leave ``results`` (table 1 keeps its rows)."""
    for label in ("", f", {FIVE}"):
        results[f"total wall time{label}"] = (
            common + results[f"renderer set-up{label}"] + results[f"render + encode MP4{label}"])
    render = lambda label: results[f"render + encode MP4{label}"]
    ratios = {
        "render + encode MP4": render(f", {FIVE}") / render(""),
        "total wall time": results[f"total wall time, {FIVE}"] / results["total wall time"],
        CPU: cpus[f", {FIVE}"] / cpus[""],
        ONE_STEP: render(f", {ONE_STEP}") / render(f", {FIVE}"),
        HELPER: render(f", {HELPER}") / render(f", {FIVE}"),
    }
    for name in (ONE_STEP, HELPER):
        for key in (f"renderer set-up, {name}", f"render + encode MP4, {name}"):
            results.pop(key)
    return ratios


def main(argv=None) -> int:
    args = _arguments(argv)
    width, height = (int(v) for v in args.size.split("x"))
    results, cpus = {}, {}  # cpus: CPU seconds of render + encode (this process and ffmpeg)
    load = os.getloadavg()[0]
    run = _common(args.seconds, results)
    m = run.animation.n_frames
    frames, frames5 = _grids(args, run, results, cpus)
    ratios = _ratios(results, cpus, run.common)
    total = results["total wall time"]
    note = (
        f"{m} frames, {frames} in the MP4, {width}x{height} 2x2 grid, "
        f"{m / results['render + encode MP4']:.0f} frames/s rendered "
        f"({m / results[f'render + encode MP4, {FIVE}']:.0f} with five views in a 3x2 grid), "
        f"{os.cpu_count()} CPUs, load average {load:.1f} at the start: other processes slow "
        f"every figure; render rows: best of {args.rounds} alternating rounds per grid; each "
        "total counts initialize, animate and OpenGL's start-up once"
    )
    print(f"{'total wall time':<34s} {total:8.3f} s  ({note})")
    print(f"old path / default (five views, render + encode): {ratios[ONE_STEP]:.2f}x; "
          f"helper thread / default: {ratios[HELPER]:.2f}x")
    print(f"five views / four views: render + encode {ratios['render + encode MP4']:.2f}x, "
          f"total {ratios['total wall time']:.2f}x (limit {RATIO_TARGET:.2f}x), CPU time of "
          f"render + encode {ratios[CPU]:.2f}x")
    ok = total < 20.0 and results["geometry, all frames, compiled"] < 0.2 and frames == m
    ok = ok and frames5 == m and ratios["total wall time"] <= RATIO_TARGET
    print("targets (total < 20 s, geometry < 0.2 s, five views <= 1.2x):",
          "met" if ok else "NOT met")
    if args.docs:
        from cassi_fit._io import atomic_write

        atomic_write(Path(args.docs) / "bench_animation.md", markdown(results, note, ratios),
                     overwrite=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
