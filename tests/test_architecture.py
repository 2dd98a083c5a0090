"""The architecture of docs/ARCHITECTURE.md, enforced (issue 10); `make lint` runs this file.

* The import-linter contracts in pyproject.toml (the layers, and no import cycle among
  cassi_fit's modules) hold; a check on a small made-up package shows that the same
  contract types do catch a cycle and an upward import.
* Every public function and method (everything in ``cassi_fit.__all__``, and the public
  functions of the modules listed there) has complete type annotations, and an array
  annotation carries a jaxtyping shape (``Float[Array, "n 2"]``), never a bare
  ``np.ndarray`` / ``jax.Array``. This reads the source (no JAX is started).
"""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

import cassi_fit

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "cassi_fit"

LINT_IMPORTS = "import sys; from importlinter.cli import lint_imports; sys.exit(lint_imports("
LINT_IMPORTS += "config_filename=sys.argv[1], no_cache=True, no_logo=True))"


def _lint_imports(config: Path, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", LINT_IMPORTS, str(config)], cwd=cwd,
                          capture_output=True, text=True)


def test_import_contracts_hold():
    """Layers and no cycles (pyproject.toml [tool.importlinter]); the output names each break."""
    out = _lint_imports(ROOT / "pyproject.toml", ROOT)
    assert out.returncode == 0, out.stdout + out.stderr


def test_the_contract_types_catch_a_cycle_and_an_upward_import(tmp_path):
    """The same contract types on a made-up package: ``low`` imports ``high`` (upward and a
    cycle, since ``high`` imports ``low``). Guards against a contract that cannot fail."""
    pkg = tmp_path / "toy"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "high.py").write_text("from . import low\n")
    (pkg / "low.py").write_text("from . import high\n")
    (tmp_path / "setup.cfg").write_text(textwrap.dedent("""\
        [importlinter]
        root_package = toy
        [importlinter:contract:layers]
        name = toy layers
        type = layers
        containers = toy
        layers =
            high
            low
        [importlinter:contract:cycles]
        name = toy cycles
        type = acyclic_siblings
        ancestors = toy
        """))
    out = _lint_imports(tmp_path / "setup.cfg", tmp_path)
    assert out.returncode != 0
    assert "toy.low is not allowed to import toy.high" in out.stdout
    assert "toy cycles BROKEN" in out.stdout


# ---- annotations of the public surface -------------------------------------------------

# jaxtyping's dtype markers: an array type inside one of them has a shape.
JAXTYPING = {"Float", "Int", "Bool", "Shaped", "Real", "Num", "Integer", "Inexact", "Complex",
             "UInt", "Key", "Float32", "Float64", "Int32", "Int64", "UInt8", "Complex64",
             "Complex128", "PRNGKeyArray"}
# Array types that need a jaxtyping shape around them.
ARRAYS = {"ndarray", "Array", "NDArray", "ArrayLike"}


def _terminal(node: ast.AST) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    return None


def bare_arrays(annotation: ast.AST) -> list[str]:
    """Array types in an annotation that are not wrapped in a jaxtyping dtype[...]."""
    if isinstance(annotation, ast.Constant) and isinstance(annotation.value, str):
        try:
            annotation = ast.parse(annotation.value, mode="eval").body
        except SyntaxError:
            return []
    if isinstance(annotation, ast.Subscript) and _terminal(annotation.value) in JAXTYPING:
        return []
    if _terminal(annotation) in ARRAYS:
        return [ast.unparse(annotation)]
    found = []
    for child in ast.iter_child_nodes(annotation):
        found += bare_arrays(child)
    return found


def function_problems(fn: ast.FunctionDef | ast.AsyncFunctionDef, method: bool) -> list[str]:
    """What a public function or method lacks: parameter or return annotations, shapes."""
    args = fn.args
    params = args.posonlyargs + args.args + args.kwonlyargs
    params += [a for a in (args.vararg, args.kwarg) if a is not None]
    if method and params and params[0].arg in ("self", "cls") and params[0].annotation is None:
        params = params[1:]
    problems = [f"parameter {p.arg} unannotated" for p in params if p.annotation is None]
    if fn.returns is None and fn.name != "__init__":
        problems.append("no return annotation")
    for node in [p.annotation for p in params] + [fn.returns]:
        if node is not None:
            problems += [f"bare array type {a}" for a in bare_arrays(node)]
    return problems


def _is_public_method(node: ast.AST) -> bool:
    return isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and (
        not node.name.startswith("_") or node.name in ("__init__", "__call__"))


def definition_problems(node: ast.AST) -> dict[str, list[str]]:
    """qualified name -> problems, for a top-level def or class (its public methods)."""
    if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
        return {node.name: function_problems(node, method=False)}
    if isinstance(node, ast.ClassDef):
        return {f"{node.name}.{m.name}": function_problems(m, method=True)
                for m in node.body if _is_public_method(m)}
    return {}


def _is_package(module: str) -> bool:
    return (PACKAGE / module.replace(".", "/") / "__init__.py").exists()


def _module_tree(module: str) -> ast.Module:
    """The syntax tree of ``module`` (dotted below cassi_fit: ``evaluate._rows``)."""
    path = PACKAGE / f"{module.replace('.', '/')}.py"
    if not path.exists():
        path = PACKAGE / module.replace(".", "/") / "__init__.py"
    return ast.parse(path.read_text(encoding="utf-8"))


def _definitions(tree: ast.Module) -> dict[str, ast.AST]:
    return {n.name: n for n in tree.body
            if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef)}


def _public_definitions(module: str) -> list[tuple[str, str]]:
    """(module, name) of a module's public functions and classes (its ``__all__`` if any)."""
    tree = _module_tree(module)
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets):
            return [(module, name) for name in ast.literal_eval(node.value)]
    return [(module, name) for name in _definitions(tree) if not name.startswith("_")]


def _top_level_statements(tree: ast.Module) -> list[ast.stmt]:
    """The module's statements, those of its ``if TYPE_CHECKING:`` blocks included."""
    out = []
    for node in tree.body:
        if (isinstance(node, ast.If) and isinstance(node.test, ast.Name)
                and node.test.id == "TYPE_CHECKING"):
            out += node.body
        else:
            out.append(node)
    return out


def _home(module: str, name: str) -> tuple[str, str]:
    """Follow ``from .x import name`` re-exports to the module that defines ``name`` (also
    those of an ``if TYPE_CHECKING:`` block: a package whose names are imported on first
    use, such as ``cassi_fit.corpus``, states them there)."""
    for node in _top_level_statements(_module_tree(module)):
        if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
            # ``from .x import`` is relative to the package itself in an __init__, else to
            # the module's parent package
            base = module if _is_package(module) else module.rpartition(".")[0]
            for alias in node.names:
                if (alias.asname or alias.name) == name:
                    return _home(f"{base}.{node.module}".lstrip("."), alias.name)
    return module, name


def annotation_offenders() -> dict[str, list[str]]:
    """``module.name -> problems`` over the public surface (empty when everything is typed)."""
    wanted = [(module, name) for name, module in cassi_fit._PUBLIC.items()]
    for module in cassi_fit._MODULES:
        wanted += _public_definitions(module)
    offenders: dict[str, list[str]] = {}
    trees: dict[str, ast.Module] = {}
    for module, name in sorted(set(wanted)):
        module, name = _home(module, name)
        tree = trees.setdefault(module, _module_tree(module))
        node = _definitions(tree).get(name)
        if node is None:  # a constant
            continue
        for qualname, problems in definition_problems(node).items():
            if problems:
                offenders[f"{module}.{qualname}"] = problems
    return offenders


def test_the_annotation_check_sees_missing_and_bare_annotations():
    code = textwrap.dedent("""\
        def ok(x: Float[Array, "n 2"], *, k: int = 1) -> Float[np.ndarray, "n"]: ...
        def untyped(x, y: int): ...
        def bare(x: np.ndarray) -> jax.Array | None: ...
        class C:
            def __init__(self, a: int): ...
            def m(self, b) -> "Array": ...
            def _private(self, c): ...
        """)
    found = {}
    for node in ast.parse(code).body:
        found.update({k: v for k, v in definition_problems(node).items() if v})
    assert found == {
        "untyped": ["parameter x unannotated", "no return annotation"],
        "bare": ["bare array type np.ndarray", "bare array type jax.Array"],
        "C.m": ["parameter b unannotated", "bare array type Array"],
    }


def test_public_functions_are_fully_annotated_with_array_shapes():
    offenders = annotation_offenders()
    listing = "\n".join(f"  {name}: {'; '.join(p)}" for name, p in sorted(offenders.items()))
    assert not offenders, f"{len(offenders)} public functions/methods lack annotations:\n{listing}"


# ---- the documented layers are the enforced ones ----------------------------------------


def _contract_layers() -> list[list[str]]:
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    (layers,) = [c for c in config["tool"]["importlinter"]["contracts"] if c["type"] == "layers"]
    assert layers["containers"] == ["cassi_fit"]
    return [[m.strip().strip("()") for m in layer.split(":")] for layer in layers["layers"]]


def _documented_layers() -> list[list[str]]:
    """The module table of docs/ARCHITECTURE.md as [[modules of layer 1], [layer 2] ...]."""
    import re

    layers: list[list[str]] = []
    for line in (ROOT / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or not re.match(r"^(\d+ \w+)?$", cells[0]) or "`" not in cells[1]:
            continue
        if cells[0]:
            layers.append([])
        layers[-1] += [m.rstrip("/*") for m in re.findall(r"`([\w/*]+)`", cells[1])]
    return layers


def test_docs_state_the_layers_the_contract_enforces():
    assert [sorted(x) for x in _documented_layers()] == [sorted(x) for x in _contract_layers()]
