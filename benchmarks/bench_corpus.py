"""Corpus runner speed: the default synthetic corpus (105 recordings) through the tasks of
``cassi evaluate`` (about a second of work per recording) and ``cassi jaw DATASET`` (tens
of milliseconds) with ``--jobs 1`` and ``--jobs 2``.

    python benchmarks/bench_corpus.py [--commands evaluate jaw] [--method closed-form]
        [--jobs 1 2] [--database 5000] [--write docs/generated/bench_corpus.md]

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


def _task(command: str, method: str, solver: str):
    """The command's task function and options, as the command runs them."""
    from cassi_fit.corpus import evaluate_task
    from cassi_fit.jaw_table import jaw_task

    if command == "evaluate":  # `cassi evaluate DATASET`: default conformation, no collisions
        return evaluate_task, {"collisions": "off", "jaw": "closed-form", "stride": 1}, None
    return jaw_task, {"method": method, "solver": solver}, True  # cassi jaw: float64


def child(command: str, jobs: int, method: str, solver: str, out: str,
          cache: str | None) -> None:
    """One setting, in this fresh process: print {"cold": s, "warm": s, ...} as JSON."""
    import concurrent.futures as cf
    import multiprocessing

    # JAX is imported by whoever computes: this process for --jobs 1, only the workers
    # otherwise (run_corpus(x64=True) sets float64 there, as `cassi jaw` computes)
    from cassi_fit.corpus import csv_text, dataset_items, run_corpus
    from cassi_fit.synth import ensure_default_corpus

    task, options, x64 = _task(command, method, solver)
    items = dataset_items(ensure_default_corpus())
    pool = None if jobs == 1 else cf.ProcessPoolExecutor(
        jobs, mp_context=multiprocessing.get_context("spawn"))
    walls, table, started = [], None, START  # cold: from this process's start
    for k in range(2):
        run = run_corpus(task, items, os.path.join(out, str(k)), executor=pool,
                         jobs=1, options=options, x64=x64,
                         compilation_cache=cache, progress=False)
        walls.append(time.perf_counter() - started)
        if run.failed:
            raise SystemExit(run.failure_summary())
        table = csv_text(run.rows())
        started = time.perf_counter()  # warm: the same workers again
    if pool is not None:
        pool.shutdown()
    print(json.dumps({"cold": walls[0], "warm": walls[1], "n": len(items), "table": table}))


def measure(command, jobs, args) -> dict:
    with tempfile.TemporaryDirectory() as out:
        done = subprocess.run(
            [sys.executable, __file__, "--child", str(jobs), "--command", command,
             "--method", args.method,
             "--solver", args.solver, "--out", out]
            + ([] if args.compilation_cache is None else
               ["--compilation-cache", args.compilation_cache]),
            check=True, capture_output=True, text=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commands", nargs="+", choices=("evaluate", "jaw"),
                        default=["evaluate", "jaw"])
    parser.add_argument("--method", default="closed-form", help="cassi jaw's method")
    parser.add_argument("--solver", default="optimistix-lm")
    parser.add_argument("--jobs", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--database", type=int, default=5000, metavar="RECORDINGS")
    parser.add_argument("--compilation-cache", metavar="DIR",
                        help="JAX's persistent compilation cache for the workers (a second "
                        "benchmark run then shows the cold cost with compiled code on disk)")
    parser.add_argument("--write", metavar="MD", help="also write the table to this file")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--command", help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        return child(args.command, args.child, args.method, args.solver, args.out,
                     args.compilation_cache)
    from cassi_fit.synth import ensure_default_corpus

    ensure_default_corpus()  # generated outside the timing
    cache = f"compilation cache {args.compilation_cache}" if args.compilation_cache else (
        "no compilation cache")
    lines = [f"cores: {os.cpu_count()}; {cache}; before: {_load()}", ""]
    rows = ["| command | --jobs | cold s | warm s | ms/recording (warm) | speed-up cold | "
            "speed-up warm |", "|---|---|---|---|---|---|---|"]
    estimates = []
    for command in args.commands:
        results = {jobs: measure(command, jobs, args) for jobs in args.jobs}
        lines += _report(command, results, args, rows, estimates)
    lines += ["", *rows, "", *estimates, "", f"after: {_load()}"]
    text = "\n".join(lines)
    print(text)
    if args.write:
        from pathlib import Path

        command = "python benchmarks/bench_corpus.py " + " ".join(
            a for a in (argv if argv is not None else sys.argv[1:]))
        Path(args.write).write_text(
            f"<!-- written by {command.strip().removeprefix('python ')} -->\n\n```\n{text}\n```\n")


def _report(command, results, args, rows, estimates) -> list[str]:
    """Print-lines for one command; appends its table rows and database estimates."""
    lines = [f"{command} ({results[args.jobs[0]]['n']} recordings): tables identical across "
             f"--jobs: {len({r['table'] for r in results.values()}) == 1}"]
    one = results.get(1)
    for jobs, r in results.items():
        cold = f"{one['cold'] / r['cold']:.2f}x" if one else ""
        warm = f"{one['warm'] / r['warm']:.2f}x" if one else ""
        rows.append(f"| {command} | {jobs} | {r['cold']:.1f} | {r['warm']:.1f} | "
                    f"{1e3 * r['warm'] / r['n']:.0f} | {cold} | {warm} |")
    if one is None:
        return lines
    per_recording, fixed = one["warm"] / one["n"], max(one["cold"] - one["warm"], 0.0)
    most = max(args.jobs)
    efficiency = min(one["warm"] / results[most]["warm"] / most, 1.0) if most > 1 else 1.0
    lines.append(f"{command}: per recording {1e3 * per_recording:.0f} ms on one core, fixed "
                 f"cost {fixed:.1f} s per run (JAX import, compilation), parallel efficiency "
                 f"{efficiency:.2f} at {most} jobs (target speed-up >= 1.7x on 2 free cores)")
    for workers in (1, 2, 8, 32, 128):
        est = fixed + args.database * per_recording / (
            workers * (efficiency if workers > 1 else 1.0))
        estimates.append(f"{command}: {args.database} recordings on {workers:3d} cores or "
                         f"workers: {est / 60:7.1f} min")
    return lines


if __name__ == "__main__":  # the 'spawn' workers import this module: keep the guard
    main()
