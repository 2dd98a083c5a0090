"""The cells a notebook kernel runs to hold an experiment's ``main`` to this process's
settings (tests/test_experiment_jaw.py, tests/test_experiment_subject_fitting.py): one
home for both."""

from __future__ import annotations

from pathlib import Path

import nbformat

EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments"

#: This process's JAX settings and warnings (tests/conftest.py, pyproject's
#: filterwarnings), then the experiment imported from experiments/.
_SETUP = """\
import sys, warnings
import jax
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")
warnings.filterwarnings("error", category=DeprecationWarning, module=r"cassi_fit.*")
sys.path.insert(0, {experiments!r})
import {module}
"""

#: A run of the experiment: its stdout, then its exit status on the last line.
_MAIN = """\
status = {module}.main({argv!r})
print("exit status", status)
"""


def setup_cell(module: str):
    """The cell that sets this process's settings in the kernel and imports ``module``."""
    return nbformat.v4.new_code_cell(_SETUP.format(experiments=str(EXPERIMENTS), module=module))


def main_cell(module: str, argv: list[str]):
    """The cell that runs ``module.main(argv)`` and prints ``exit status N`` last."""
    return nbformat.v4.new_code_cell(_MAIN.format(module=module, argv=argv))
