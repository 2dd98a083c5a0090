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


def test_every_public_name_resolves():
    for name in cassi_fit.__all__:
        assert getattr(cassi_fit, name) is not None, name


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
