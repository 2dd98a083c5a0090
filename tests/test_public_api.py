"""One public surface (issue 10): every advertised name resolves, ``import cassi_fit`` is cheap
and has no side effects, and the README and the notebooks import from ``cassi_fit`` only."""

from __future__ import annotations

import ast
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import cassi_fit

ROOT = Path(__file__).resolve().parents[1]


_RESOLVE = """
import importlib, json, sys
import cassi_fit
for module in sorted(set(cassi_fit._PUBLIC.values())):  # every home imported first
    importlib.import_module("cassi_fit." + module)
out = {}
for name in cassi_fit.__all__:
    value = getattr(cassi_fit, name)
    if name in cassi_fit._MODULES:
        out[name] = [value is sys.modules["cassi_fit." + name], "module"]
        continue
    home = importlib.import_module("cassi_fit." + cassi_fit._PUBLIC[name])
    out[name] = [value is getattr(home, name), getattr(value, "__module__", None)]
print(json.dumps(out))
"""


def test_every_public_name_resolves_to_what_it_names():
    """In a fresh process where every home module has been imported (which binds each
    submodule to the package under its name: ``initialize`` is a module and a function),
    each name of ``__all__`` is the very object of the module ``_PUBLIC`` names (a name
    of ``_MODULES`` is that module), defined in cassi_fit's own code, in that module or
    below it."""
    resolved = json.loads(_fresh_python(_RESOLVE))
    assert sorted(resolved) == sorted(cassi_fit.__all__)
    for name, (same, module) in resolved.items():
        assert same, f"cassi_fit.{name} is not the object its home module holds"
        if module not in ("module", None):
            home = f"cassi_fit.{cassi_fit._PUBLIC[name]}"
            assert module == home or module.startswith(home + "."), (name, module, home)


def test_all_lists_exactly_the_lazy_names_and_the_type_checking_imports():
    """``__all__``, the lazy table and the ``from ._x import Y as Y`` block agree."""
    lazy = set(cassi_fit._PUBLIC) | set(cassi_fit._MODULES)
    assert sorted(cassi_fit.__all__) == sorted(lazy)
    assert len(cassi_fit.__all__) == len(set(cassi_fit.__all__))
    tree = ast.parse((ROOT / "cassi_fit" / "__init__.py").read_text(encoding="utf-8"))
    (block,) = [n for n in tree.body if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.dump(n.test)]
    stated = {}
    for node in block.body:
        assert isinstance(node, ast.ImportFrom) and node.level == 1, ast.dump(node)
        for alias in node.names:
            assert alias.asname == alias.name, f"write `{alias.name} as {alias.name}`"
            stated[alias.name] = node.module or alias.name
    assert stated == {**cassi_fit._PUBLIC, **{m: m for m in cassi_fit._MODULES}}


@pytest.mark.parametrize("package", ["corpus", "ema"])
def test_a_lazy_subpackage_states_its_names_once_and_each_resolves(package):
    """``cassi_fit.corpus`` and ``cassi_fit.ema`` import their names on first use (a
    command needs one of their modules, not all): the lazy table, ``__all__`` and the
    ``TYPE_CHECKING`` block agree, and each name is its home module's object."""
    import importlib

    module = importlib.import_module(f"cassi_fit.{package}")
    tree = ast.parse((ROOT / "cassi_fit" / package / "__init__.py").read_text(encoding="utf-8"))
    (block,) = [n for n in tree.body if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.dump(n.test)]
    stated = {}
    for node in block.body:
        assert isinstance(node, ast.ImportFrom), ast.dump(node)
        for alias in node.names:
            assert alias.asname in (None, alias.name), alias.name
            stated[alias.name] = "." * node.level + node.module
    assert stated == module._NAMES
    assert sorted(module.__all__) == sorted(module._NAMES)
    for name, home in module._NAMES.items():
        source = importlib.import_module(home, module.__name__)
        assert getattr(module, name) is getattr(source, name), name


def test_modules_offered_by_name_are_modules():
    """A submodule name in ``__all__`` means the module, whatever was imported before."""
    import cassi_fit.animate  # noqa: F401  (binds the attribute the way the import system does)

    for name in cassi_fit._MODULES:
        assert type(getattr(cassi_fit, name)).__name__ == "module", name


def _fresh_python(code: str, env: dict | None = None) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env=env, cwd=ROOT)
    return out.stdout


def test_import_is_cheap():
    code = "import sys, cassi_fit; print('jax' in sys.modules, 'OpenGL' in sys.modules)"
    assert _fresh_python(code).split() == ["False", "False"]


def test_import_leaves_the_environment_alone():
    """``import cassi_fit`` must not choose JAX's platform (or anything else) for the user."""
    env = {k: v for k, v in os.environ.items() if k != "JAX_PLATFORMS"}
    code = ("import os, json; before = dict(os.environ); import cassi_fit; "
            "cassi_fit.__all__; print(json.dumps([before == dict(os.environ), "
            "os.environ.get('JAX_PLATFORMS')]))")
    assert json.loads(_fresh_python(code, env)) == [True, None]


def test_the_command_uses_the_cpu_unless_the_user_chose(monkeypatch, capsys):
    from cassi_fit.cli import build_parser, main

    assert "JAX_PLATFORMS" in build_parser().format_help()
    monkeypatch.delenv("JAX_PLATFORMS", raising=False)
    main([])
    assert os.environ["JAX_PLATFORMS"] == "cpu"
    monkeypatch.setenv("JAX_PLATFORMS", "cuda")
    main([])
    assert os.environ["JAX_PLATFORMS"] == "cuda"
    capsys.readouterr()


def _readme_python() -> list[str]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    return re.findall(r"```python\n(.*?)```", text, flags=re.S)


def _notebook_code(path: Path) -> list[str]:
    cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
    return ["".join(c["source"]) for c in cells if c["cell_type"] == "code"]


SOURCES = [("README.md", code) for code in _readme_python()] + [
    (p.name, code) for p in sorted((ROOT / "notebooks").glob("*.ipynb")) for code in
    _notebook_code(p)]


@pytest.mark.parametrize(("where", "code"), SOURCES)
def test_examples_import_from_cassi_fit_only(where, code):
    """The README's and the notebooks' imports use the public surface, nothing deeper."""
    tree = ast.parse(code)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("cassi_fit"):
            assert node.module == "cassi_fit", f"{where}: from {node.module} import ..."
            for alias in node.names:
                assert alias.name in cassi_fit.__all__, f"{where}: {alias.name} is not public"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                assert not alias.name.startswith("cassi_fit."), f"{where}: import {alias.name}"
