"""Rendering speed: ms per frame and frames/s for the 2x2 grid and for single views.

    .venv/bin/python benchmarks/bench_render.py [--frames 200] [--size 640x480] [--markers]
                                                [--docs DIR]

Renders the repository's face model with the jaw opening and closing (a new vertex array
every frame, as in an animation), through one reused ``Renderer``; prints wall time and
process CPU time (all threads: llvmpipe rasterises on worker threads) per frame. The
pipeline's target: a 5 s recording (~730 frames) rendered as the 640x480 grid and encoded
to MP4 in under 20 s on 2 CPU cores. With ``--docs DIR`` the printed table is also
written to ``DIR/bench_render.md`` (``make bench`` passes ``--docs docs/generated``; the
README quotes it byte for byte).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np


def frames_of_model(n_frames: int):
    """(model, (n_frames, V, 3) vertices): the jaw opening and closing twice."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from cassi_fit.deform import default_params, deform
    from cassi_fit.face_model import load_model

    model = load_model()
    thetas = 0.2 * (1 - np.cos(np.linspace(0, 4 * np.pi, n_frames))) / 2

    def one(theta):
        params = eqx.tree_at(lambda p: p.jaw_theta, default_params(model), theta)
        return deform(model, params)

    vertices = jax.jit(jax.vmap(one))(jnp.asarray(thetas))
    return model, np.asarray(vertices)


def time_frames(renderer, frames, markers, caption: bool) -> tuple[float, float]:
    """(wall ms, CPU ms) per frame, after one warm-up frame."""
    renderer.render(frames[0], markers=markers)
    wall, cpu = time.perf_counter(), time.process_time()
    for k, vertices in enumerate(frames):
        text = f"BENCH sentence   t = {k / 147:7.3f} s   line {k + 1}" if caption else None
        renderer.render(vertices, markers=markers, caption=text)
    n = len(frames)
    return (time.perf_counter() - wall) / n * 1e3, (time.process_time() - cpu) / n * 1e3


def markdown(rows: list[tuple], header: str) -> str:
    """``bench_render.md``: the first line names the command, then the measured table.
    ``rows``: (label, wall ms, CPU ms, set-up s) per case."""
    lines = [
        "<!-- written by `python benchmarks/bench_render.py --docs docs/generated`; do not "
        "edit: `make bench` rewrites it -->",
        "# Rendering speed",
        "",
        f"One run of `benchmarks/bench_render.py`: {header}. Wall and process CPU time per "
        "frame (all threads), after one warm-up frame, through one reused `Renderer`.",
        "",
        "| case | wall ms/frame | frames/s | CPU ms/frame | set-up s |",
        "|---|---|---|---|---|",
    ]
    lines += [f"| {label} | {wall:.1f} | {1e3 / wall:.1f} | {cpu:.1f} | {setup:.2f} |"
              for label, wall, cpu, setup in rows]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200, help="frames per measurement")
    parser.add_argument("--size", default="640x480", help="output image size WxH")
    parser.add_argument("--markers", action="store_true", help="draw 2 x 8 pellet markers")
    parser.add_argument("--docs", metavar="DIR", help="also write DIR/bench_render.md")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.split("x"))

    from cassi_fit.render import PAPER_VIEWS, VIEWS, Renderer

    model, frames = frames_of_model(args.frames)
    markers = None
    if args.markers:
        sites = np.asarray(
            [
                frames[0][model.landmarks[k]]
                for k in ("UL", "LL", "T1", "T2", "T3", "T4", "MNI", "MNM")
            ]
        )
        markers = {"measured": sites, "model": sites + 1.0}
    header = (
        f"{len(frames)} frames, {width}x{height}, {frames.shape[1]} vertices, "
        f"{len(model.faces)} triangles, {os.cpu_count()} CPUs, load average "
        f"{os.getloadavg()[0]:.1f} at the start (other processes slow every figure)"
    )
    print(header)
    rows = []
    cases = [("grid (4 views)", PAPER_VIEWS, 0), ("grid (5 views)", VIEWS, 0)]
    cases += [("grid + caption", PAPER_VIEWS, 0), ("grid, 4x MSAA", PAPER_VIEWS, 4)]
    cases += [(f"single: {v}", (v,), 0) for v in VIEWS]
    for label, views, samples in cases:
        start = time.perf_counter()
        renderer = Renderer(model, size=(width, height), views=views, antialias=samples)
        setup = time.perf_counter() - start
        wall, cpu = time_frames(renderer, frames, markers, caption="caption" in label)
        renderer.close()
        rows.append((label, wall, cpu, setup))
        print(
            f"{label:<18s} {wall:6.1f} ms/frame  {1e3 / wall:6.1f} frames/s  "
            f"(CPU {cpu:5.1f} ms/frame, set-up {setup:4.2f} s)"
        )
    if args.docs:
        from pathlib import Path

        from cassi_fit._io import atomic_write

        atomic_write(Path(args.docs) / "bench_render.md", markdown(rows, header), overwrite=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
