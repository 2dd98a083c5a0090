"""The library's default precision, float32, in the suite (issue 22): everything else runs in
float64 (tests/conftest.py). A fresh process with x64 off (and rank promotion raising)
initializes and animates a short recording with a least-squares jaw fit (fixed pivot), and
takes a gradient of the deformation; the results are float32 and agree with this process's float64
ones within float32's precision.

JAX's x64 switch is a process-wide setting that must not change once arrays exist, hence
the separate process rather than ``jax.experimental.enable_x64(False)`` here.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

_FLOAT32 = """
import json, sys
import jax
assert not jax.config.jax_enable_x64
jax.config.update("jax_numpy_rank_promotion", "raise")
sys.path.insert(0, sys.argv[2])
import numpy as np
from float32_case import case
out = {k: np.asarray(v) for k, v in case().items()}
np.savez(sys.argv[1], **out)
print(json.dumps({k: str(v.dtype) for k, v in out.items()}))
"""


@pytest.fixture(scope="module")
def float32_run(tmp_path_factory):
    """The case run in a fresh float32 process: ``(arrays, their dtypes)``."""
    out = tmp_path_factory.mktemp("float32") / "case.npz"
    env = {**os.environ, "JAX_ENABLE_X64": "0", "JAX_PLATFORMS": "cpu"}
    done = subprocess.run([sys.executable, "-c", _FLOAT32, str(out), str(Path(__file__).parent)],
                          capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    dtypes = json.loads(done.stdout.strip().splitlines()[-1])
    with np.load(out) as arrays:
        return {k: arrays[k] for k in arrays.files}, dtypes


@pytest.fixture(scope="module")
def float64_run():
    import jax
    from float32_case import case

    assert jax.config.jax_enable_x64
    return {k: np.asarray(v) for k, v in case().items()}


def test_the_float32_path_computes_in_float32(float32_run, float64_run):
    _, dtypes = float32_run
    assert dtypes == {k: "float32" for k in float64_run}, dtypes
    assert {str(v.dtype) for v in float64_run.values()} == {"float64"}


@pytest.mark.parametrize(("name", "atol_mm"), [
    ("vertices", 5e-4),  # every vertex of every frame, mm (measured: 3.5e-5)
    ("pellets_model", 2e-4),  # the model's pellet sites, mm (measured: 7e-6)
])
def test_float32_agrees_with_float64(float32_run, float64_run, name, atol_mm):
    """Coordinates of about 100 mm carry about 1e-5 mm of float32 rounding; the pipeline's
    steps (rotations, the tongue's volume, the jaw fit) grow it a little (measured on this
    recording: 3.5e-5 mm at most for a vertex); the bounds leave a tenfold margin."""
    low, high = float32_run[0][name], float64_run[name]
    assert low.shape == high.shape and np.all(np.isfinite(low))
    error = np.abs(low.astype(np.float64) - high).max()
    assert error < atol_mm, error


def test_float32_gradient_agrees_with_float64(float32_run, float64_run):
    """d(weighted vertex sum)/d(parameters) of the deformation at a posed face."""
    low, high = float32_run[0]["gradient"], float64_run["gradient"]
    scale = np.abs(high).max()
    assert scale > 0 and np.abs(low - high).max() < 1e-5 * scale  # measured: 5e-8
