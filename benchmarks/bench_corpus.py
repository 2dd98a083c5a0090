"""Corpus runner speed: the default synthetic corpus (105 recordings) through the
``cassi jaw DATASET`` task with ``--jobs 1`` and ``--jobs 2``.

    python benchmarks/bench_corpus.py [--method closed-form] [--jobs 1 2] [--database 5000]

Each setting runs in a fresh Python process, timed from its start to the last row as a
user meets it ("cold": JAX imported, workers started, the fit compiled once per worker),
then a second time on the same, warm workers ("warm": the steady cost). From these:
per-recording cost (warm / recordings), fixed cost per run (cold - warm), the speed-up
of 2 jobs over 1 cold and warm (target >= 1.7x on 2 free cores), and an estimate for a
database of ``--database`` recordings on N cores or M Dask workers,
``fixed + recordings * per_recording / (workers * efficiency)``, with the parallel
efficiency measured warm. The machine's load average is printed before and after: on a
shared machine the speed-up measures the cores actually free.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

START = time.perf_counter()


def _load() -> str:
    return "load average " + ", ".join(f"{x:.2f}" for x in os.getloadavg())


def child(jobs: int, method: str, solver: str, out: str, cache: str | None) -> None:
    """One setting, in this fresh process: print {"cold": s, "warm": s, ...} as JSON."""
    import concurrent.futures as cf
    import multiprocessing

    # JAX is imported by whoever computes: this process for --jobs 1, only the workers
    # otherwise (run_corpus(x64=True) sets float64 there, as `cassi jaw` computes)
    from cassi_fit.corpus import csv_text, dataset_items, jaw_task, run_corpus
    from cassi_fit.synth import ensure_default_corpus

    items = dataset_items(ensure_default_corpus())
    pool = None if jobs == 1 else cf.ProcessPoolExecutor(
        jobs, mp_context=multiprocessing.get_context("spawn"))
    walls, table, started = [], None, START  # cold: from this process's start
    for k in range(2):
        run = run_corpus(jaw_task, items, os.path.join(out, str(k)), executor=pool,
                         jobs=1, options={"method": method, "solver": solver}, x64=True,
                         compilation_cache=cache, progress=False)
        walls.append(time.perf_counter() - started)
        if run.failed:
            raise SystemExit(run.failure_summary())
        table = csv_text(run.rows())
        started = time.perf_counter()  # warm: the same workers again
    if pool is not None:
        pool.shutdown()
    print(json.dumps({"cold": walls[0], "warm": walls[1], "n": len(items), "table": table}))


def measure(jobs, args) -> dict:
    with tempfile.TemporaryDirectory() as out:
        done = subprocess.run(
            [sys.executable, __file__, "--child", str(jobs), "--method", args.method,
             "--solver", args.solver, "--out", out]
            + ([] if args.compilation_cache is None else
               ["--compilation-cache", args.compilation_cache]),
            check=True, capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="closed-form")
    parser.add_argument("--solver", default="optimistix-lm")
    parser.add_argument("--jobs", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--database", type=int, default=5000, metavar="RECORDINGS")
    parser.add_argument("--compilation-cache", metavar="DIR",
                        help="JAX's persistent compilation cache for the workers (a second "
                        "benchmark run then shows the cold cost with compiled code on disk)")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        return child(args.child, args.method, args.solver, args.out, args.compilation_cache)
    from cassi_fit.synth import ensure_default_corpus

    ensure_default_corpus()  # generated outside the timing
    cache = f"compilation cache {args.compilation_cache}" if args.compilation_cache else (
        "no compilation cache")
    print(f"jaw method {args.method}; {cache}; cores: {os.cpu_count()}; {_load()}")
    results = {}
    for jobs in args.jobs:
        r = results[jobs] = measure(jobs, args)
        print(f"--jobs {jobs}: cold {r['cold']:6.2f} s ({1e3 * r['cold'] / r['n']:5.1f} ms per "
              f"recording), warm {r['warm']:6.2f} s ({1e3 * r['warm'] / r['n']:5.1f} ms per "
              f"recording), {r['n']} recordings")
    print("tables identical across --jobs:", len({r["table"] for r in results.values()}) == 1)
    if 1 not in results:
        return
    one = results[1]
    per_recording, fixed = one["warm"] / one["n"], max(one["cold"] - one["warm"], 0.0)
    efficiency = 1.0
    for jobs in (j for j in args.jobs if j > 1):
        r = results[jobs]
        cold, warm = one["cold"] / r["cold"], one["warm"] / r["warm"]
        efficiency = min(warm / jobs, 1.0)
        print(f"speed-up --jobs {jobs} over --jobs 1: cold {cold:.2f}x, warm {warm:.2f}x "
              f"(target >= 1.7x for 2 jobs on 2 free cores)")
    print(f"per recording {1e3 * per_recording:.1f} ms (one core), fixed cost {fixed:.1f} s "
          f"per run (JAX import, compilation), parallel efficiency {efficiency:.2f}")
    for workers in (1, 2, 8, 32, 128):
        est = fixed + args.database * per_recording / (workers * (efficiency if workers > 1
                                                                  else 1.0))
        print(f"estimate, {args.database} recordings on {workers:3d} cores/workers: "
              f"{est / 60:6.1f} min")
    print(_load())


if __name__ == "__main__":  # the 'spawn' workers import this module: keep the guard
    main()
