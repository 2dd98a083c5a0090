"""What a warm ``cassi jaw RECORDING.txy`` imports and compiles (issue 30: every jaw method
within 1.5x of the import floor, ``benchmarks/bench_startup.py``): none of the articulograph
readers, the corpus runner, the calibration, jaxopt or the ``scipy.linalg`` package (JAX's
LAPACK kernels take SciPy's two function tables alone), and nothing compiled: every kernel
is loaded from the exported kernels' folder, and no other JAX operation runs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cassi_fit.txy import PelletTrack, write_txy

#: Imported by no warm ``cassi jaw`` of a pellet file (a prefix stands for its modules, but
#: for SciPy's two LAPACK function tables, loaded alone: :data:`LAPACK_TABLES`).
NOT_IMPORTED = ("cassi_fit.ema", "cassi_fit.corpus._executor", "cassi_fit.corpus._cluster",
                "cassi_fit.corpus._items", "cassi_fit.calibration", "cassi_fit.sound",
                "cassi_fit.jaw_fit._jaxopt_adapter", "cassi_fit._cli.animate", "scipy.linalg",
                "numpy.f2py")
LAPACK_TABLES = ("scipy.linalg.cython_blas", "scipy.linalg.cython_lapack")

_RUN = """
import json, sys
import jax
compiles = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, duration, **kw: compiles.append(event)
    if event == "/jax/core/compile/backend_compile_duration" else None)
from cassi_fit.cli import main
status = main(sys.argv[1:])
print(json.dumps({"status": status, "compiles": len(compiles), "modules": sorted(sys.modules)}))
"""


@pytest.fixture(scope="module")
def pellet_file(tmp_path_factory):
    """A short plausible recording: the jaw opening about a pivot, the rest held."""
    n = 40
    theta = np.linspace(0.0, 0.2, n)
    reference = np.array([[-2.0, -18.0], [-35.0, -24.0]])
    pivot = np.array([-88.0, -8.0])
    c, s = np.cos(theta), np.sin(theta)
    rel = reference[None] - pivot  # p' = R(theta) (p - q) + q, theta > 0 opening
    jaw = np.stack([c[:, None] * rel[..., 0] + s[:, None] * rel[..., 1],
                    -s[:, None] * rel[..., 0] + c[:, None] * rel[..., 1]], -1) + pivot
    positions = np.zeros((n, 8, 2))
    positions[:, :6] = [[15.0, 18.0], [9.0, -21.0], [-17.0, 1.0], [-28.0, 8.0],
                        [-39.0, 15.0], [-53.0, 17.0]]
    positions[:, 6:] = jaw
    track = PelletTrack(times=np.arange(n) * 0.006866, positions=positions,
                        valid=np.ones((n, 8, 2), bool))
    path = tmp_path_factory.mktemp("data") / "jw99_tp001.txy"
    write_txy(path, track)
    return path


def _jaw(pellet_file: Path, cache: Path, method: str) -> dict:
    env = {**os.environ, "CASSI_COMPILE_CACHE": str(cache), "JAX_PLATFORMS": "cpu"}
    env.pop("CASSI_EXPORT_CACHE", None)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    out = cache.parent / f"{method}.csv"
    done = subprocess.run([sys.executable, "-c", _RUN, "jaw", str(pellet_file), "--csv",
                           str(out), "--force", "--method", method],
                          env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("method", ["frame-fit", "fixed-pivot"])
def test_a_warm_jaw_command_imports_and_compiles_only_what_it_needs(pellet_file, tmp_path,
                                                                    method):
    cache = tmp_path / "cache"
    cold = _jaw(pellet_file, cache, method)  # traces and compiles, fills the folders
    assert cold["status"] == 0 and cold["compiles"] > 0
    warm = _jaw(pellet_file, cache, method)
    assert warm["status"] == 0
    assert warm["compiles"] == 0  # every kernel loaded, no other JAX operation compiled
    imported = [m for m in warm["modules"] if m not in LAPACK_TABLES
                and any(m == p or m.startswith(p + ".") for p in NOT_IMPORTED)]
    assert imported == []
    assert set(LAPACK_TABLES) <= set(warm["modules"])  # LAPACK readied (both use it)
