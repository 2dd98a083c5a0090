"""Jaw-rotation speed, everything measured in one run on the same frames.

    python benchmarks/bench_jaw.py [--frames N]

Prints: the closed form jitted (float32, large batch) vs the same formula in plain numpy;
each per-frame fit (optimistix, jaxopt; vmapped) vs scipy.optimize.least_squares called per
frame; the fixed-pivot and smooth-pivot fits of a 2,000-frame recording after compilation.
Targets (2 CPU cores): closed form >= 1e7 frames/s; batched fit >= 100x scipy per frame;
fixed pivot < 1 s; smooth pivot about 1 s. The closed form runs in float32; the fits in
float64 (as in the tests; JAX's default would silently make them float32).
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

REFERENCE = np.array([[-2.0, -18.0], [-35.0, -24.0]])
PIVOT = np.array([-88.0, -8.0])


def frames(n, seed=0):
    """``n`` jaw frames (n, 2, 2) mm: the reference turned about PIVOT by speech-like angles
    (0-11.5 degrees) plus 0.3 mm noise. (An earlier version broadcast the wrong axes and
    returned one configuration for every frame, its pellets 118 mm apart instead of 33.)"""
    rng = np.random.default_rng(seed)
    theta = 0.2 * np.sin(np.linspace(0, 40, n)) ** 2
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    rel = REFERENCE - PIVOT  # (2, 2): [pellet, xy]
    moved = np.stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]], -1)
    return moved + PIVOT + rng.normal(0, 0.3, (n, 2, 2))


def numpy_closed_form(reference, current):
    """The sound closed form (atan2, MNI-mapped translation) in plain numpy."""
    u = reference[0] - reference[1]
    v = current[:, 0] - current[:, 1]
    theta = np.arctan2(v[:, 0] * u[1] - v[:, 1] * u[0], v[:, 0] * u[0] + v[:, 1] * u[1])
    c, s = np.cos(theta), np.sin(theta)
    p = reference[0]
    t = current[:, 0] - np.stack([c * p[0] + s * p[1], -s * p[0] + c * p[1]], -1)
    half = theta / 2
    ch, sh = np.cos(half), np.sin(half)
    ux, uy = ch * t[:, 0] - sh * t[:, 1], sh * t[:, 0] + ch * t[:, 1]
    return theta, t, np.stack([uy, -ux], -1) / (2 * sh[:, None])


def best_of(fn, repeats=3):
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=4_000_000)
    parser.add_argument("--fit-frames", type=int, default=2000)
    args = parser.parse_args(argv)
    jax.config.update("jax_enable_x64", True)  # the fits; the closed form stays float32
    from cassi_fit import jaw, jaw_fit

    big = frames(args.frames).astype(np.float32)
    ref32 = REFERENCE.astype(np.float32)
    cf = jax.jit(jax.vmap(jaw.closed_form, in_axes=(None, 0)))
    dev = jnp.asarray(big)
    t_jax = best_of(lambda: jax.block_until_ready(cf(ref32, dev)))
    t_np = best_of(lambda: numpy_closed_form(ref32, big))
    print(f"closed form, {args.frames} frames float32: jit {args.frames / t_jax / 1e6:.1f} M "
          f"frames/s, numpy {args.frames / t_np / 1e6:.1f} M frames/s, ratio {t_np / t_jax:.1f}x")

    from scipy.optimize import least_squares

    n = args.fit_frames
    cur = frames(n, seed=1)

    def scipy_loop():
        out = np.empty((n, 3))
        for k in range(n):
            def res(y, k=k):
                c, s = np.cos(y[0]), np.sin(y[0])
                p = REFERENCE
                m = np.stack([c * p[:, 0] + s * p[:, 1] + y[1], -s * p[:, 0] + c * p[:, 1] + y[2]], -1)
                return (m - cur[k]).ravel()
            out[k] = least_squares(res, np.zeros(3), method="lm").x
        return out

    t0 = time.perf_counter()
    scipy_loop()
    t_scipy = (time.perf_counter() - t0) / n
    print(f"scipy.optimize.least_squares per frame: {t_scipy * 1e6:.0f} us/frame")
    for solver in jaw_fit.SOLVERS:
        kernel = jaw_fit._frame_kernel("frame-fit", solver)
        t = best_of(lambda k=kernel: jax.block_until_ready(k(REFERENCE, cur))) / n
        print(f"frame-fit {solver:18s} (vmap, {n} frames): {t * 1e6:7.2f} us/frame, "
              f"{t_scipy / t:6.0f}x scipy")
    for solver in ("optimistix-lm", "jaxopt-lm"):
        jaw_fit.fit_jaw(REFERENCE, cur, method="fixed-pivot", solver=solver)  # compile
        t = best_of(lambda s=solver: jaw_fit.fit_jaw(REFERENCE, cur, method="fixed-pivot",
                                                     solver=s))
        print(f"fixed-pivot {solver} on a {n}-frame recording (after compilation): {t:.3f} s")
    fit = jaw_fit.fit_jaw(REFERENCE, cur, method="smooth-pivot")  # compile
    t = best_of(lambda: jaw_fit.fit_jaw(REFERENCE, cur, method="smooth-pivot"))
    print(f"smooth-pivot {fit.solver} on a {n}-frame recording (after compilation): {t:.3f} s"
          f" (converged: {fit.converged})")


if __name__ == "__main__":
    main()
