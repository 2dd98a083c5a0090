"""Rendering speed: ms per frame and frames/s for the 2x2 grid and for single views.

    .venv/bin/python benchmarks/bench_render.py [--frames 200] [--size 640x480] [--markers]

Renders the repository's face model with the jaw opening and closing (a new vertex array
every frame, as in an animation), through one reused ``Renderer``; prints wall time and
process CPU time (all threads: llvmpipe rasterises on worker threads) per frame. The
pipeline's target: a 5 s recording (~730 frames) rendered as the 640x480 grid and encoded
to MP4 in under 20 s on 2 CPU cores.
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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=200, help="frames per measurement")
    parser.add_argument("--size", default="640x480", help="output image size WxH")
    parser.add_argument("--markers", action="store_true", help="draw 2 x 8 pellet markers")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.split("x"))

    from cassi_fit.render import VIEWS, Renderer

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
    print(
        f"{len(frames)} frames, {width}x{height}, {frames.shape[1]} vertices, "
        f"{len(model.faces)} triangles, {os.cpu_count()} CPUs"
    )
    cases = [("grid (4 views)", VIEWS, 0), ("grid + caption", VIEWS, 0)]
    cases += [("grid, 4x MSAA", VIEWS, 4)]
    cases += [(f"single: {v}", (v,), 0) for v in VIEWS]
    for label, views, samples in cases:
        start = time.perf_counter()
        renderer = Renderer(model, size=(width, height), views=views, antialias=samples)
        setup = time.perf_counter() - start
        wall, cpu = time_frames(renderer, frames, markers, caption="caption" in label)
        renderer.close()
        print(
            f"{label:<18s} {wall:6.1f} ms/frame  {1e3 / wall:6.1f} frames/s  "
            f"(CPU {cpu:5.1f} ms/frame, set-up {setup:4.2f} s)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
