"""Jaw-rotation speed, everything measured in one run, both sides timed the same way.

    python benchmarks/bench_jaw.py [--fit-frames N] [--frames N] [--sizes 2000,20000,...]
                                   [--markdown docs/generated/bench_jaw.md]

Prints, and writes as markdown (so that docs quote a generated table, never a stale figure):

1. the closed form jitted (float32, large batch) vs the same formula in plain numpy;
2. the per-frame fit, JAX batched (``fit_jaw`` with a :class:`FrameFit`, vmapped, every
   solver) vs ``scipy.optimize.least_squares`` called per frame with an analytic Jacobian:
   (a) both from the same cold start (theta = 0, t = 0), (b) both from the same warm start
   (the two-point Procrustes motion), (c) the vectorised numpy two-point Procrustes, the
   analytic floor. Every time is the median of ``--repeats`` (>= 5) runs after one untimed
   run; JAX's compile time is reported on its own and as the first call (compile + run) for
   one recording. Target: batched fit >= 100x scipy from the same start; the table says
   whether it is met.
3. whole-recording fits (fixed pivot, smooth pivot) of a ``--fit-frames`` recording;
4. smooth-pivot scaling: time and peak memory (each size in its own process, so the peak
   is that size's) from 2k to 200k lines. Target: 200k lines < 10 s, memory linear.

The fits run in float64 (as in the tests and ``cassi jaw``); the closed form in float32.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REFERENCE = np.array([[-2.0, -18.0], [-35.0, -24.0]])
PIVOT = np.array([-88.0, -8.0])
ROOT = Path(__file__).resolve().parents[1]


def frames(n, seed=0, rate=0.02):
    """``n`` jaw frames (n, 2, 2) mm: the reference turned about PIVOT by speech-like angles
    (0-11.5 degrees; ``rate`` rad per frame: 0.02 = an opening per 157 frames, about 1 s,
    at every length) plus 0.3 mm noise."""
    rng = np.random.default_rng(seed)
    theta = 0.2 * np.sin(rate * np.arange(n)) ** 2
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
    with np.errstate(divide="ignore", invalid="ignore"):  # theta = 0: pivot at infinity
        return theta, t, np.stack([uy, -ux], -1) / (2 * sh[:, None])


def numpy_procrustes(reference, current):
    """Two-point least-squares motion, vectorised numpy: (n, 3) = (theta, tx, ty)."""
    c_ref, c_cur = reference.mean(0), current.mean(1)
    u, v = reference[0] - c_ref, current[:, 0] - c_cur
    theta = np.arctan2(u[1] * v[:, 0] - u[0] * v[:, 1], u[0] * v[:, 0] + u[1] * v[:, 1])
    c, s = np.cos(theta), np.sin(theta)
    t = c_cur - np.stack([c * c_ref[0] + s * c_ref[1], -s * c_ref[0] + c * c_ref[1]], -1)
    return np.column_stack([theta, t])


def median_time(fn, repeats):
    """Median wall time of ``repeats`` calls after one untimed call (s)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def scipy_fit(current, start):
    """scipy least_squares (MINPACK LM, analytic Jacobian) per frame from ``start`` (n, 3)."""
    from scipy.optimize import least_squares

    p = REFERENCE
    out = np.empty((len(current), 3))
    for k in range(len(current)):
        target = current[k]

        def res(y, target=target):
            c, s = np.cos(y[0]), np.sin(y[0])
            moved = np.stack([c * p[:, 0] + s * p[:, 1] + y[1], -s * p[:, 0] + c * p[:, 1] + y[2]],
                             -1)
            return (moved - target).ravel()

        def jac(y):
            c, s = np.cos(y[0]), np.sin(y[0])
            j = np.zeros((4, 3))
            j[0::2, 0] = -s * p[:, 0] + c * p[:, 1]
            j[1::2, 0] = -c * p[:, 0] - s * p[:, 1]
            j[0::2, 1] = 1.0
            j[1::2, 2] = 1.0
            return j

        out[k] = least_squares(res, start[k], jac=jac, method="lm").x
    return out


class Report:
    """Lines printed and kept for the markdown file."""

    def __init__(self):
        self.lines = []

    def __call__(self, text=""):
        print(text, flush=True)
        self.lines.append(text)


def bench_closed_form(out, n, repeats):
    import jax
    import jax.numpy as jnp

    from cassi_fit import jaw

    big = frames(n).astype(np.float32)
    ref32 = REFERENCE.astype(np.float32)
    cf = jax.jit(jax.vmap(jaw.closed_form, in_axes=(None, 0)))
    dev = jnp.asarray(big)
    t_jax = median_time(lambda: jax.block_until_ready(cf(ref32, dev)), repeats)
    t_np = median_time(lambda: numpy_closed_form(ref32, big), repeats)
    out(f"| closed form, {n:,} frames, float32 | {n / t_jax / 1e6:.1f} M frames/s (jit) | "
        f"{n / t_np / 1e6:.1f} M frames/s (numpy) | {t_np / t_jax:.1f}x |")


def bench_frame_fit(out, n, repeats):
    """Tables (a), (b), (c) and the compile times."""
    from cassi_fit.jaw_fit import FrameFit, fit_jaw, jaw_solver
    from cassi_fit.options import SOLVERS

    cur = frames(n, seed=1)
    cold = np.zeros((n, 3))

    def warm():
        return numpy_procrustes(REFERENCE, cur)

    t_floor = median_time(warm, repeats) / n
    s_cold = median_time(lambda: scipy_fit(cur, cold), repeats) / n
    s_warm = median_time(lambda: scipy_fit(cur, warm()), repeats) / n
    out(f"Per-frame fit, {n} frames of 0.3 mm noise, float64; median of {repeats} runs; "
        f"us per frame.")
    out()
    out("| solver | (a) JAX cold | scipy cold | ratio | (b) JAX warm | scipy warm | ratio | "
        "first call (compile + run) | compile |")
    out("|---|---|---|---|---|---|---|---|---|")
    ratios = []
    for name in SOLVERS:
        solver = jaw_solver(name)
        cold_method, warm_method = FrameFit(solver=solver, start=cold), FrameFit(solver=solver)
        t0 = time.perf_counter()
        fit = fit_jaw(REFERENCE, cur, method=cold_method)  # first call: compiles
        first = time.perf_counter() - t0
        j_cold = median_time(lambda m=cold_method: fit_jaw(REFERENCE, cur, method=m), repeats)
        j_warm = median_time(lambda m=warm_method: fit_jaw(REFERENCE, cur, method=m), repeats)
        assert fit.converged, name
        np.testing.assert_allclose(fit.theta, warm()[:, 0], atol=1e-7)
        ratios.append((name, s_cold / (j_cold / n), s_warm / (j_warm / n)))
        out(f"| {name} | {j_cold / n * 1e6:.2f} | {s_cold * 1e6:.0f} | {ratios[-1][1]:.0f}x | "
            f"{j_warm / n * 1e6:.2f} | {s_warm * 1e6:.0f} | {ratios[-1][2]:.0f}x | "
            f"{first:.2f} s | {max(first - j_cold, 0.0):.2f} s |")
    out()
    out(f"(c) analytic floor, vectorised numpy two-point Procrustes: {t_floor * 1e6:.3f} us "
        f"per frame ({s_warm / t_floor:.0f}x faster than scipy warm).")
    best = max(ratios, key=lambda r: min(r[1], r[2]))
    met = min(best[1], best[2]) >= 100.0
    out(f"Target >= 100x scipy from the same start: {'MET' if met else 'NOT MET'} "
        f"(best solver {best[0]}: {best[1]:.0f}x cold, {best[2]:.0f}x warm).")
    out("JAX times are whole `fit_jaw` calls (status, covariances, pivots included); the "
        "first call of a process also compiles the shared helpers.")


def bench_recording_fits(out, n, repeats):
    from cassi_fit.jaw_fit import FixedPivot, SmoothPivot, fit_jaw, jaw_solver

    cur = frames(n, seed=1)
    out()
    out(f"| whole-recording fit, {n} frames | first call (compile + run) | after compilation |")
    out("|---|---|---|")
    for label, method in (("fixed-pivot optimistix-lm", FixedPivot()),
                          ("fixed-pivot jaxopt-lm", FixedPivot(solver=jaw_solver("jaxopt-lm"))),
                          ("smooth-pivot (block-tridiagonal LM)", SmoothPivot())):
        t0 = time.perf_counter()
        fit = fit_jaw(REFERENCE, cur, method=method)
        first = time.perf_counter() - t0
        t = median_time(lambda m=method: fit_jaw(REFERENCE, cur, method=m), repeats)
        out(f"| {label} | {first:.2f} s | {t:.3f} s{'' if fit.converged else ' NOT converged'} |")


def _peak_rss_mb():
    """This process's peak resident memory (MB): VmHWM, which (unlike ru_maxrss, inherited
    across exec from the parent) starts afresh in a new program."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def smooth_child(n, rate=0.02):
    """One smooth-pivot fit of ``n`` lines in this process: JSON of times and peak memory."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from cassi_fit.jaw_fit import SmoothPivot, fit_jaw

    cur = frames(n, seed=2, rate=rate)
    t0 = time.perf_counter()
    fit = fit_jaw(REFERENCE, cur, method=SmoothPivot())
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    fit_jaw(REFERENCE, cur, method=SmoothPivot())
    second = time.perf_counter() - t0
    peak_mb = _peak_rss_mb()
    print(json.dumps(dict(n=n, first=first, second=second, peak_mb=peak_mb,
                          converged=fit.converged, rate=rate)))


def _smooth_run(n, rate=0.02):
    proc = subprocess.run([sys.executable, __file__, "--smooth-child", str(n), "--rate",
                           str(rate)], capture_output=True, text=True, timeout=1800,
                          env=dict(os.environ, JAX_PLATFORMS="cpu"))
    if proc.returncode != 0:
        return proc.stderr.strip().splitlines()[-1]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def bench_smooth_scaling(out, sizes):
    out()
    out("Smooth-pivot scaling (each size in a fresh process; peak = maximum resident memory "
        "of that process, JAX included).")
    out()
    out("| lines | first call (compile + run) | after compilation | peak memory | converged |")
    out("|---|---|---|---|---|")
    base = last = None
    for n in sizes:
        r = _smooth_run(n)
        if isinstance(r, str):
            out(f"| {n:,} | failed: {r} | | | |")
            continue
        base, last = base or r, r
        out(f"| {n:,} | {r['first']:.2f} s | {r['second']:.2f} s | {r['peak_mb']:.0f} MB | "
            f"{r['converged']} |")
    if base is not None and last is not base:
        grow = last["n"] / base["n"]
        extra = (last["peak_mb"] - base["peak_mb"]) * 2**20 / (last["n"] - base["n"])
        met = last["n"] < 200_000 or last["second"] < 10.0
        out()
        out(f"Growth from {base['n']:,} to {last['n']:,} lines ({grow:.0f}x): time after "
            f"compilation x{last['second'] / base['second']:.0f}, memory "
            f"+{last['peak_mb'] - base['peak_mb']:.0f} MB (about {extra:.0f} bytes per line "
            f"above the 2,000-line process). Target 200,000 lines < 10 s after compilation: "
            f"{'MET' if met else 'NOT MET'}; compilation (once per recording length) comes "
            f"on top.")
        slow = _smooth_run(sizes[-1], rate=0.02 / 5)
        if not isinstance(slow, str):
            out(f"Slow movement (an opening per 5 s, little pivot information per knot), "
                f"{slow['n']:,} lines: {slow['second']:.2f} s after compilation, converged: "
                f"{slow['converged']}.")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=4_000_000)
    parser.add_argument("--fit-frames", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--sizes", default="2000,20000,50000,200000")
    parser.add_argument("--markdown", default=str(ROOT / "docs" / "generated" / "bench_jaw.md"))
    parser.add_argument("--smooth-child", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--rate", type=float, default=0.02, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.smooth_child:
        return smooth_child(args.smooth_child, args.rate)
    if args.repeats < 5:
        parser.error("--repeats must be at least 5 (medians of fewer runs are not reported)")
    import jax

    jax.config.update("jax_enable_x64", True)  # the fits; the closed form stays float32
    out = Report()
    out("<!-- written by benchmarks/bench_jaw.py; do not edit -->")
    out(f"Measured {time.strftime('%Y-%m-%d')} on {platform.machine()}, {os.cpu_count()} "
        f"CPUs, JAX {jax.__version__} (CPU).")
    out()
    out("| closed form | JAX | numpy | ratio |")
    out("|---|---|---|---|")
    bench_closed_form(out, args.frames, args.repeats)
    out()
    bench_frame_fit(out, args.fit_frames, args.repeats)
    bench_recording_fits(out, args.fit_frames, args.repeats)
    bench_smooth_scaling(out, [int(s) for s in args.sizes.split(",") if s])
    if args.markdown:
        path = Path(args.markdown)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("\n".join(out.lines) + "\n", encoding="utf-8")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
