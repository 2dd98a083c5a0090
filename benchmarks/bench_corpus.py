"""Corpus runner speed: the default synthetic corpus (105 recordings) through the tasks of
``cassi evaluate`` (about a second of work per recording) and ``cassi jaw DATASET`` (tens
of milliseconds) with ``--jobs 1`` and ``--jobs 2``.

    python benchmarks/bench_corpus.py [--commands evaluate jaw] [--method closed-form]
        [--jobs 1 2] [--recordings N] [--database 5000]
        [--write docs/generated/bench_corpus.md]

Each setting runs in a fresh Python process, timed from its start to the last row as a
user meets it ("first run": JAX imported, workers started, the functions compiled or
loaded once per worker), then a second time on the same, warm workers ("steady": the
per-recording cost). Each setting runs twice so: with an empty compilation cache folder
("clean cache") and again with the folder the first filled ("warm cache", as every run
after the first on a machine). The workers are the pool ``run_corpus(jobs=N)`` makes
(``corpus.process_pool``: each worker limited to its share of the cores). From these:
per-recording cost (steady / recordings), the fixed cost of a run (first run - steady)
with a clean and a warm cache (target: under 5 s warm), the speed-up of 2 jobs over 1
(target >= 1.7x on 2 free cores), and an estimate for a database of ``--database``
recordings on N cores or M Dask workers, ``fixed + recordings * per_recording / (workers
* efficiency)``, with the parallel efficiency measured steady. The machine's load average
is printed before and after: on a shared machine the speed-up measures the cores actually
free.
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
    if command == "evaluate":  # `cassi evaluate DATASET`: its defaults
        from cassi_fit.evaluate import evaluate_task
        from cassi_fit.run_spec import run_spec

        return evaluate_task, {"spec": run_spec("improved")}, None
    from cassi_fit.jaw_fit import jaw_method
    from cassi_fit.jaw_table import jaw_spec, jaw_task

    spec = jaw_spec(jaw=jaw_method(method, solver=solver))  # cassi jaw's: float64
    return jaw_task, {"spec": spec}, True


def child(command: str, jobs: int, method: str, solver: str, out: str,
          cache: str | None, recordings: int | None) -> None:
    """One setting, in this fresh process: print {"cold": s, "warm": s, ...} as JSON."""
    # JAX is imported by whoever computes: this process for --jobs 1, only the workers
    # otherwise (run_corpus(x64=True) sets float64 there, as `cassi jaw` computes)
    from cassi_fit.corpus import (
        csv_text,
        dataset_items,
        process_pool,
        run_corpus,
        use_compile_cache,
    )
    from cassi_fit.synth import ensure_default_corpus

    task, options, x64 = _task(command, method, solver)
    items = dataset_items(ensure_default_corpus())[:recordings]
    if jobs == 1:  # as the command line does in its own process
        use_compile_cache(cache)
    pool = None if jobs == 1 else process_pool(jobs, x64=x64,
                                               compilation_cache=cache or False)
    walls, table, started = [], None, START  # cold: from this process's start
    for k in range(2):
        run = run_corpus(task, items, os.path.join(out, str(k)), executor=pool,
                         jobs=1, options=options, x64=x64,
                         compilation_cache=cache or False, progress=False)
        walls.append(time.perf_counter() - started)
        if run.failed:
            raise SystemExit(run.failure_summary())
        table = csv_text(run.rows())
        started = time.perf_counter()  # warm: the same workers again
    if pool is not None:
        pool.shutdown()
    print(json.dumps({"cold": walls[0], "warm": walls[1], "n": len(items), "table": table}))


def measure(command, jobs, args) -> dict:
    """The setting run twice in fresh processes: with a clean compilation cache, then
    with the one the first filled. {"clean": {...}, "warm": {...}}."""
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        for name in ("clean", "warm"):
            with tempfile.TemporaryDirectory() as folder:
                done = subprocess.run(
                    [sys.executable, __file__, "--child", str(jobs), "--command", command,
                     "--method", args.method, "--solver", args.solver, "--out", folder,
                     "--compilation-cache", cache]
                    + ([] if args.recordings is None else
                       ["--recordings", str(args.recordings)]),
                    capture_output=True, text=True)
            if done.returncode != 0:
                raise SystemExit(done.stderr.strip()[-2000:])
            out[name] = json.loads(done.stdout.strip().splitlines()[-1])
            print(f"{command} --jobs {jobs}, {name} cache: first run "
                  f"{out[name]['cold']:.1f} s, steady {out[name]['warm']:.1f} s", flush=True)
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commands", nargs="+", choices=("evaluate", "jaw"),
                        default=["evaluate", "jaw"])
    parser.add_argument("--method", default="closed-form", help="cassi jaw's method")
    parser.add_argument("--solver", default="optimistix-lm")
    parser.add_argument("--jobs", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--database", type=int, default=5000, metavar="RECORDINGS")
    parser.add_argument("--recordings", type=int, metavar="N",
                        help="only the first N recordings of the corpus (default all)")
    parser.add_argument("--compilation-cache", help=argparse.SUPPRESS)
    parser.add_argument("--write", metavar="MD", help="also write the table to this file")
    parser.add_argument("--child", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--command", help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        return child(args.command, args.child, args.method, args.solver, args.out,
                     args.compilation_cache, args.recordings)
    from cassi_fit.synth import ensure_default_corpus

    ensure_default_corpus()  # generated outside the timing
    lines = [f"cores: {os.cpu_count()}; before: {_load()}", ""]
    rows = ["| command | --jobs | first run, clean cache s | first run, warm cache s | "
            "steady s | ms/recording (steady) | fixed cost, warm cache s | speed-up steady |",
            "|---|---|---|---|---|---|---|---|"]
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
    first = results[args.jobs[0]]["warm"]
    tables = {r[c]["table"] for r in results.values() for c in ("clean", "warm")}
    lines = [f"{command} ({first['n']} recordings): tables identical across --jobs and "
             f"caches: {len(tables) == 1}"]
    one = results.get(1, {}).get("warm")
    for jobs, r in results.items():
        warm, clean = r["warm"], r["clean"]
        fixed = max(warm["cold"] - warm["warm"], 0.0)
        speed = f"{one['warm'] / warm['warm']:.2f}x" if one else ""
        rows.append(f"| {command} | {jobs} | {clean['cold']:.1f} | {warm['cold']:.1f} | "
                    f"{warm['warm']:.1f} | {1e3 * warm['warm'] / warm['n']:.0f} | "
                    f"{fixed:.1f} | {speed} |")
    if one is None:
        return lines
    per_recording, fixed = one["warm"] / one["n"], max(one["cold"] - one["warm"], 0.0)
    clean_fixed = max(results[1]["clean"]["cold"] - results[1]["clean"]["warm"], 0.0)
    most = max(args.jobs)
    speed_up = one["warm"] / results[most]["warm"]["warm"] if most > 1 else 1.0
    efficiency = min(speed_up / most, 1.0)
    lines.append(f"{command}: per recording {1e3 * per_recording:.0f} ms on one core; fixed "
                 f"cost per run {clean_fixed:.1f} s with a clean compilation cache, "
                 f"{fixed:.1f} s warm (target < 5 s: "
                 f"{'met' if fixed < 5 else 'NOT MET'}); {most} jobs: {speed_up:.2f}x "
                 f"(target >= 1.7x on 2 free cores: "
                 f"{'met' if speed_up >= 1.7 or most == 1 else 'NOT MET'})")
    for workers in (1, 2, 8, 32, 128):
        est = fixed + args.database * per_recording / (
            workers * (efficiency if workers > 1 else 1.0))
        estimates.append(f"{command}: {args.database} recordings on {workers:3d} cores or "
                         f"workers: {est / 60:7.1f} min")
    return lines


if __name__ == "__main__":  # the 'spawn' workers import this module: keep the guard
    main()
