"""Tracing repeated in every process (issue 30, part 3): the smooth-pivot jaw kernel
called as ``cassi jaw`` calls it (traced, then found in the warm compilation cache) against
the same computation serialized once with ``jax.export`` and deserialized (no tracing),
each in a fresh process with a warm cache; beside them the warm ``cassi jaw --method
smooth-pivot`` and a bare ``python -c "import jax, jax.numpy as jnp, cassi_fit;
jnp.zeros(1).block_until_ready()"``. Ratios measured in this one run.

    python benchmarks/bench_trace.py [--recording FILE.txy]

A measurement, not a change: the toolkit does not ship exported kernels (yet). JAX's
serialization needs the ``flatbuffers`` package (``pip install flatbuffers``); without it
the script says so and stops.
"""

from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _recording_default() -> Path | None:
    for base in (*ROOT.parents, Path("/work")):
        candidate = base / "shared/data/xrmb_jw11/jw11_tp005.txy"
        if candidate.is_file():
            return candidate
    return None


def _setup():
    import jax

    jax.config.update("jax_enable_x64", True)  # as cassi jaw does
    from cassi_fit.corpus._process import default_compile_cache, use_compile_cache

    use_compile_cache(default_compile_cache())
    return jax


def capture(recording: Path, work: Path) -> None:
    """Run ``cassi jaw --method smooth-pivot`` here, keep the kernel's arguments, export
    the kernel at them (outputs flattened) and save both."""
    _setup()
    from jax import export, jit, tree

    from cassi_fit import cli
    from cassi_fit.jaw_fit import _methods

    calls = []
    kernel = _methods.smooth_pivot_kernel

    def keep(config, *args):
        calls.append((config, args))
        return kernel(config, *args)

    _methods.smooth_pivot_kernel = keep
    cli.main(["jaw", str(recording), "--csv", str(work / "jaw.csv"), "--force", "--method",
              "smooth-pivot"])
    config, args = calls[0]
    exported = export.export(jit(lambda *a: tree.leaves(kernel(config, *a))))(*args)
    (work / "kernel.bin").write_bytes(exported.serialize())
    with open(work / "args.pkl", "wb") as fh:
        pickle.dump((config, tree.map(lambda x: __import__("numpy").asarray(x), args)), fh)


def call(work: Path, how: str) -> None:
    """One kernel call in this fresh process: ``traced`` or ``exported``; prints seconds."""
    start = time.perf_counter()
    jax = _setup()
    import jax.numpy as jnp

    import cassi_fit  # noqa: F401

    jnp.zeros(1).block_until_ready()
    with open(work / "args.pkl", "rb") as fh:
        config, args = pickle.load(fh)
    ready = time.perf_counter()
    if how == "traced":
        from cassi_fit.jaw_fit._kernels import smooth_pivot_kernel

        out = smooth_pivot_kernel(config, *args)
    else:
        from jax import export

        out = export.deserialize(bytearray((work / "kernel.bin").read_bytes())).call(*args)
    jax.block_until_ready(out)
    print(f"{time.perf_counter() - ready:.4f} {ready - start:.4f}")


def child(argv: list[str], cache: Path) -> str:
    env = {**os.environ, "CASSI_COMPILE_CACHE": str(cache), "JAX_PLATFORMS": "cpu"}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    done = subprocess.run([sys.executable, *argv], env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed: {done.stderr[-800:]}")
    return done.stdout.strip().splitlines()[-1] if done.stdout.strip() else ""


def wall(argv: list[str], cache: Path) -> float:
    start = time.perf_counter()
    child(argv, cache)
    return time.perf_counter() - start


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=_recording_default())
    parser.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        how, folder = args.child
        if how == "capture":
            capture(args.recording, Path(folder))
        else:
            call(Path(folder), how)
        return 0
    try:
        import flatbuffers  # noqa: F401  (jax.export's serialization)
    except ImportError:
        print("SKIPPED: jax.export's serialization needs 'flatbuffers' (pip install "
              "flatbuffers)", file=sys.stderr)
        return 0
    if args.recording is None or not args.recording.is_file():
        print("SKIPPED: the real JW11 recording is absent (../shared/data/xrmb_jw11/)",
              file=sys.stderr)
        return 0
    me = [__file__, "--recording", str(args.recording), "--child"]
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        cache = work / "cache"
        child([*me, "capture", folder], cache)
        jaw = ["-m", "cassi_fit.cli", "jaw", str(args.recording), "--csv",
               str(work / "jaw.csv"), "--force", "--method", "smooth-pivot"]
        wall(jaw, cache)  # the cache warm for the whole command too
        jaw_s = wall(jaw, cache)
        bare_s = wall(["-c", "import jax, jax.numpy as jnp, cassi_fit; "
                       "jnp.zeros(1).block_until_ready()"], cache)
        times = {}
        for how in ("traced", "exported", "traced", "exported"):  # the second of each: warm
            times[how] = [float(v) for v in child([*me, how, folder], cache).split()]
    traced, exported = times["traced"][0], times["exported"][0]
    load = os.getloadavg()[0]
    print(f"load average {load:.1f}; {os.cpu_count()} CPUs; {args.recording.name}")
    print(f"cassi jaw --method smooth-pivot, warm: {jaw_s:.2f} s; bare jax + cassi_fit "
          f"start-up: {bare_s:.2f} s; ratio {jaw_s / bare_s:.2f} (target <= 1.5)")
    print(f"smooth-pivot kernel in a fresh process, warm cache: traced {traced:.3f} s, "
          f"exported (deserialized, no tracing) {exported:.3f} s; traced / exported "
          f"{traced / exported:.2f}; the time saved is {traced - exported:.2f} s, "
          f"{(traced - exported) / jaw_s:.0%} of the whole command")
    return 0


if __name__ == "__main__":
    sys.exit(main())
