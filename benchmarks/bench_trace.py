"""Tracing repeated in every process (issue 30, part 3): each exported kernel's first call
in a fresh process of its own, with the compilation cache warm, traced as ``eqx.filter_jit``
traces it (``CASSI_EXPORT_CACHE=off``, the toolkit before the exported kernels), traced and
exported into an empty folder (the first process on a machine), and loaded from the folder
the previous process filled (every later one); beside them the second call (the computation
alone). Best of ``--rounds`` rounds; ratios measured in this one run.

    python benchmarks/bench_trace.py [--recording FILE.txy] [--rounds 2] [--docs DIR]

The kernels' arguments are those of a real run, kept once by a first process: the
calibration of subject S01 of a synthetic corpus (two tasks; ``calibrate_residuals``) and
``cassi jaw`` with each method on the recording (the real JW11 one when
``../shared/data/xrmb_jw11/`` is there, else S01's sentence; ``jaw_fit._kernels``); beside
them ``frames._geometry_kernel`` at the arguments an ``animate`` of the recording gives it
(its last call: every frame, with the penetration depths measured, not the rest sites'
call of ``initialize`` before it). Every process runs in float64, as ``cassi jaw`` does. With ``--docs DIR`` the table is written to ``DIR/bench_trace.md``.
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
MODES = ("traced", "empty", "warm")


def _recording_default() -> Path | None:
    for base in (*ROOT.parents, Path("/work")):
        candidate = base / "shared/data/xrmb_jw11/jw11_tp005.txy"
        if candidate.is_file():
            return candidate
    return None


def _setup():
    import jax

    jax.config.update("jax_enable_x64", True)
    from cassi_fit.corpus._process import default_compile_cache, use_compile_cache

    use_compile_cache(default_compile_cache())
    return jax


def capture(work: Path, recording: Path | None) -> None:
    """Run the calibration, ``cassi jaw`` with each method and an animation here, keep
    each exported kernel's first arguments (``frames._geometry_kernel``'s last: the
    animation's) in ``work/args.pkl``."""
    jax = _setup()
    import equinox as eqx
    import numpy as np

    from cassi_fit import cli, synth
    from cassi_fit._exported import Exported
    from cassi_fit.calibrate import calibrate_subject
    from cassi_fit.dataset import Dataset

    calls: dict[str, tuple] = {}
    call = Exported.__call__

    def keep(self, *args, **kwargs):
        if any(isinstance(a, jax.core.Tracer) for a in jax.tree.leaves((args, kwargs))):
            pass  # called inside another kernel's trace: not a call a process makes
        elif self.name == "cassi_fit.frames._geometry_kernel":
            calls[self.name] = (args, kwargs)  # the last: animate's, every frame measured
        else:
            calls.setdefault(self.name, (args, kwargs))
        return call(self, *args, **kwargs)

    Exported.__call__ = keep
    root = synth.generate_corpus(work / "corpus", n_subjects=1, seed=0,
                                 tasks=("tp106", synth.SENTENCE_TASK))
    ds = Dataset(root)
    calibrate_subject([ds.load("S01", t) for t in ds.tasks("S01")])
    if recording is None:
        recording = ds.pellet_path("S01", synth.SENTENCE_TASK)
    for method in ("closed-form", "frame-fit", "fixed-pivot", "smooth-pivot"):
        cli.main(["jaw", str(recording), "--csv", str(work / "jaw.csv"), "--force",
                  "--method", method])
    from cassi_fit.animate import animate
    from cassi_fit.dataset import load_recording
    from cassi_fit.initialize import initialize

    state = initialize(load_recording(recording))
    animate(state, load_recording(recording))
    as_numpy = jax.tree.map(lambda a: np.asarray(a) if eqx.is_array(a) else a, calls)
    with open(work / "args.pkl", "wb") as fh:
        pickle.dump(as_numpy, fh)


def call(work: Path, only: str) -> None:
    """The kept kernel ``only`` (``all``: each in turn)'s first and second call in this
    fresh process; prints ``name first-call seconds, second-call seconds, traces, loads``
    per kernel."""
    jax = _setup()
    import importlib

    import jax.numpy as jnp

    jnp.zeros(1).block_until_ready()
    with open(work / "args.pkl", "rb") as fh:
        calls = pickle.load(fh)
    for name, (args, kwargs) in calls.items():
        if only not in ("all", name):
            continue
        module, attr = name.rsplit(".", 1)
        kernel = getattr(importlib.import_module(module), attr)
        start = time.perf_counter()
        jax.block_until_ready(kernel(*args, **kwargs))
        first = time.perf_counter() - start
        start = time.perf_counter()
        jax.block_until_ready(kernel(*args, **kwargs))  # compiled, in memory: the run alone
        print(f"{name} {first:.4f} {time.perf_counter() - start:.4f} {kernel.traces} "
              f"{kernel.loads}", flush=True)


def child(argv: list[str], cache: Path, exported: str
          ) -> dict[str, tuple[float, float, int, int]]:
    env = {**os.environ, "CASSI_COMPILE_CACHE": str(cache), "CASSI_EXPORT_CACHE": exported,
           "JAX_PLATFORMS": "cpu"}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    done = subprocess.run([sys.executable, __file__, *argv], env=env, capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed: {done.stderr[-1500:]}")
    out = {}
    for line in done.stdout.splitlines():
        parts = line.split()
        if len(parts) == 5 and parts[0].startswith("cassi_fit."):
            out[parts[0]] = (float(parts[1]), float(parts[2]), int(parts[3]), int(parts[4]))
    return out


def markdown(rows: list[tuple], note: str) -> str:
    lines = [
        "<!-- written by `python benchmarks/bench_trace.py --docs docs/generated`; do not "
        "edit: `make bench` rewrites it -->",
        "# Exported kernels: a fresh process's first call, traced against loaded",
        "",
        f"One run of `benchmarks/bench_trace.py` ({note}). Each cell is a new process "
        "whose compilation cache is warm, calling one kernel; seconds of the kernel's first call (trace or "
        "load, the executable from the compilation cache, the call). *traced*: "
        "`CASSI_EXPORT_CACHE=off`, as `eqx.filter_jit` traces it in every process; *empty "
        "folder*: traced and exported (the first process on a machine); *loaded*: the next "
        "process, which deserializes it instead of tracing; *run*: the second call in the "
        "same process (the computation alone). *Start-up* is a first call less the run: "
        "what the process pays before the kernel computes.",
        "",
        "| kernel | traced s | empty folder s | loaded s | run s | traced / loaded | "
        "start-up traced / loaded |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, traced, empty, warm, run in rows:
        lines.append(f"| {name} | {traced:.2f} | {empty:.2f} | {warm:.2f} | {run:.2f} | "
                     f"{traced / warm:.1f} | {(traced - run) / max(warm - run, 0.01):.1f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=_recording_default())
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--docs", metavar="DIR", help="also write DIR/bench_trace.md")
    parser.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        how, folder, *only = args.child
        if how == "capture":
            capture(Path(folder), args.recording)
        else:
            call(Path(folder), *only)
        return 0
    try:
        import flatbuffers  # noqa: F401  (jax.export's serialization, a dependency)
    except ImportError:
        raise SystemExit("jax.export's serialization needs 'flatbuffers' (a dependency of "
                         "cassi_fit: reinstall the project)") from None
    me = ["--child"] if args.recording is None else ["--recording", str(args.recording),
                                                     "--child"]
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as folder:
        work = Path(folder)
        cache = work / "cache"
        child([*me, "capture", folder], cache, "off")
        # the compilation cache warm for both ways (filter_jit's and the exported call's)
        names = list(child([*me, "call", folder, "all"], cache, "off"))
        child([*me, "call", folder, "all"], cache, str(work / "warm-up"))
        rounds = []
        for k in range(args.rounds):  # a new empty folder each round; a process per kernel
            times = {mode: {} for mode in MODES}
            for name in names:
                folder_k = str(work / f"exported{k}")
                for mode, exported in zip(MODES, ("off", folder_k, folder_k), strict=True):
                    times[mode].update(child([*me, "call", folder, name], cache, exported))
            rounds.append(times)
    after = os.getloadavg()
    rows = []
    for name in rounds[0]["traced"]:
        best = []
        for mode, counts in zip(MODES, ((0, 0), (1, 0), (0, 1)), strict=True):
            for times in rounds:
                if times[mode][name][2:] != counts:
                    raise SystemExit(f"{name}, {mode}: traces/loads {times[mode][name][2:]}, "
                                     f"not {counts}: the folder did not work as it should")
            best.append(min(times[mode][name][0] for times in rounds))
        run = min(times[mode][name][1] for times in rounds for mode in MODES)
        short = name.removeprefix("cassi_fit.")
        rows.append((f"`{short}`", *best, run))
    total = [sum(r[k] for r in rows) for k in (1, 2, 3, 4)]
    rows.append(("all of them", *total))
    source = args.recording.name if args.recording else "synthetic S01 sentence"
    note = (f"jaw kernels on {source}; {os.cpu_count()} CPUs; load average {load[0]:.1f} "
            f"before, {after[0]:.1f} after (other processes slow every wall time); best of "
            f"{args.rounds} round(s)")
    text = markdown(rows, note)
    print(text)
    if args.docs:
        from cassi_fit._io import atomic_write

        atomic_write(Path(args.docs) / "bench_trace.md", text, overwrite=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
