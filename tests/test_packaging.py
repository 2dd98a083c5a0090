"""A normal install carries the face model and runs outside the checkout (issue 10).

The wheel is built from a copy of the sources (so a stale ``build/`` folder cannot supply
files the package configuration forgot), installed with ``pip install --target`` into a
temporary folder, and used from a temporary working directory by a Python started with
``-S``: no ``.pth`` file runs, so neither the checkout nor an editable install is on the
path, only the installed wheel and the test environment's site-packages (for the
dependencies).
"""

from __future__ import annotations

import csv
import fnmatch
import json
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("pyproject.toml", "README.md", "cassi_fit", "model")


def _package_data_patterns() -> list[str]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    setuptools = config["tool"]["setuptools"]
    assert setuptools["package-dir"]["cassi_fit.model"] == "model"
    assert "cassi_fit.model" in setuptools["packages"]
    return setuptools["package-data"]["cassi_fit.model"]


def test_every_model_data_file_is_package_data():
    """Each file the loader reads from model/ matches a package-data pattern (fast check)."""
    patterns = _package_data_patterns()
    data = [p.name for p in (ROOT / "model").iterdir() if p.suffix in (".csv", ".json")]
    assert {"vertices.csv", "faces.csv", "model.json", "parameters.csv"} <= set(data)
    missed = [n for n in data if not any(fnmatch.fnmatch(n, pat) for pat in patterns)]
    assert not missed, f"model files left out of the wheel: {missed}"


def test_every_subpackage_is_packaged():
    """Each folder of cassi_fit/ with an __init__.py is listed in [tool.setuptools] packages, so
    a wheel cannot silently leave a subpackage (evaluate/, render/, ...) out (fast check)."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    listed = set(config["tool"]["setuptools"]["packages"])
    found = {
        ".".join(init.parent.relative_to(ROOT).parts)
        for init in (ROOT / "cassi_fit").rglob("__init__.py")
        if "__pycache__" not in init.parts
    }
    assert found <= listed, f"subpackages missing from pyproject.toml: {sorted(found - listed)}"


PIP = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]


def _copy_sources(dest: Path) -> Path:
    """What a source distribution holds, copied (no build/ or egg-info left over)."""
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, dest / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            dest.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, dest / name)
    return dest


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """A folder into which the freshly built wheel is installed (``pip --target``)."""
    work = tmp_path_factory.mktemp("wheel")
    src = _copy_sources(work / "src")
    wheels = work / "dist"
    subprocess.run([*PIP, "wheel", "--no-deps", "-w", str(wheels), str(src)],
                   check=True, cwd=work)
    (wheel,) = wheels.glob("cassi_fit-*.whl")
    target = work / "target"
    subprocess.run([*PIP, "install", "--no-deps", "--target", str(target), str(wheel)],
                   check=True, cwd=work)
    return target


def _dependencies_env(*first: Path) -> dict[str, str]:
    """The environment with PYTHONPATH = ``first`` + this test run's site-packages."""
    deps = [p for p in sys.path if Path(p).name in ("site-packages", "dist-packages")]
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["PYTHONPATH"] = os.pathsep.join([*map(str, first), *deps])
    env.setdefault("JAX_PLATFORMS", "cpu")
    return env


def _run_installed(target: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    """Run ``python -S *args`` seeing only the installed wheel and the dependencies."""
    out = subprocess.run([sys.executable, "-S", *args], cwd=cwd, env=_dependencies_env(target),
                         capture_output=True, text=True)
    assert out.returncode == 0, f"{args}\nstdout:\n{out.stdout}\nstderr:\n{out.stderr}"
    return out


@pytest.mark.slow
def test_wheel_contains_the_model(installed):
    for name in ("vertices.csv", "faces.csv", "model.json", "parameters.csv"):
        assert (installed / "cassi_fit" / "model" / name).is_file(), name
    # the viewer's inline script and three.js's licence (cassi view needs no network)
    for name in ("viewer.js", "THREE_LICENSE"):
        assert (installed / "cassi_fit" / "viewer" / "assets" / name).is_file(), name


LOAD = """
import sys
from pathlib import Path
import cassi_fit
from cassi_fit import load_model
from cassi_fit.face_model import default_model_dir

here, checkout = Path(sys.argv[1]).resolve(), Path(sys.argv[2]).resolve()
assert Path(cassi_fit.__file__).resolve().is_relative_to(here), cassi_fit.__file__
assert not any(Path(p or ".").resolve() == checkout for p in sys.path), sys.path
assert default_model_dir().resolve().is_relative_to(here), default_model_dir()
print(load_model().vertices.shape[0])
"""


@pytest.mark.slow
def test_installed_wheel_loads_the_model_and_runs_commands(installed, tmp_path):
    out = _run_installed(installed, tmp_path, "-c", LOAD, str(installed), str(ROOT))
    with open(ROOT / "model" / "vertices.csv", newline="", encoding="utf-8") as fh:
        rows = sum(1 for row in csv.reader(fh) if row) - 1
    assert int(out.stdout.split()[-1]) == rows

    corpus = tmp_path / "corpus"
    _run_installed(installed, tmp_path, "-m", "cassi_fit.cli", "synth", str(corpus),
                   "--subjects", "1", "--tasks", "tp106", "--no-audio")
    info = _run_installed(installed, tmp_path, "-m", "cassi_fit.cli", "info", str(corpus),
                          "--json")
    text = json.dumps(json.loads(info.stdout))
    assert "S01" in text and "tp106" in text.lower()


EDITABLE = """
from pathlib import Path
import cassi_fit.model
from cassi_fit.face_model import default_model_dir, load_model

print(Path(cassi_fit.model.__file__).parent, default_model_dir(), load_model().vertices.shape[0])
"""


@pytest.mark.slow
def test_editable_install_reads_the_model_folder_through_the_mapping(tmp_path):
    """``pip install -e`` of a source tree: ``cassi_fit.model`` is that tree's ``model/``."""
    src = _copy_sources(tmp_path / "src")
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    subprocess.run([*PIP, "--python", str(python), "install", "--no-deps", "-e", str(src)],
                   check=True, cwd=tmp_path)
    # The dependencies come after the venv's own site-packages (a .pth sorted last), so that
    # its editable hook, not one of this test environment's, is the one imported.
    deps = [p for p in sys.path if Path(p).name in ("site-packages", "dist-packages")]
    (site,) = (venv / "lib").glob("python3*/site-packages")
    (site / "zz_test_dependencies.pth").write_text("\n".join(deps) + "\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env.setdefault("JAX_PLATFORMS", "cpu")
    out = subprocess.run([str(python), "-c", EDITABLE], cwd=tmp_path, env=env, text=True,
                         capture_output=True)
    assert out.returncode == 0, out.stderr
    package, folder, n = out.stdout.split()
    assert Path(package) == Path(folder) == src / "model"
    assert int(n) > 0
