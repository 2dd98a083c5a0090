"""mkdocs hook of the API reference (mkdocs.yml): one page per home module of
``cassi_fit.__all__``, made at build time from ``cassi_fit._PUBLIC`` (read statically, so
the build imports neither cassi_fit nor JAX), in the sections of the path of one recording
(docs/ARCHITECTURE.md). A module the sections do not name gets a page under "More", so every
public name is always on some page."""

from __future__ import annotations

import ast
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
SECTIONS = (
    ("Running a recording", ("run_spec", "pipeline", "initialize", "animate")),
    ("Data", ("dataset", "txy", "pellets", "mistracks", "quality", "gaps", "outlines",
              "headmeasures", "labels", "ema", "synth")),
    ("Face model", ("face_model", "deform", "tongue", "palate", "pharynx", "rigid")),
    ("Jaw", ("jaw", "jaw_fit", "jaw_table")),
    ("Subject calibration", ("conformation", "calibrate", "calibrate_corpus")),
    ("Outputs", ("video", "render", "evaluate", "reports")),
    ("Corpus", ("corpus",)),
    ("Base", ("status", "options", "errors")),
)


def public_surface() -> tuple[dict[str, list[str]], tuple[str, ...]]:
    """``({home module: [public names, in __all__'s order]}, namespace modules)`` from
    cassi_fit/__init__.py's ``_PUBLIC``, ``_MODULES`` and ``__all__``."""
    tree = ast.parse((ROOT / "cassi_fit" / "__init__.py").read_text(encoding="utf-8"))
    values = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name):
            name = node.targets[0].id
            if name in ("_PUBLIC", "_MODULES", "__all__"):
                values[name] = ast.literal_eval(node.value)
    homes: dict[str, list[str]] = {}
    for name in values["__all__"]:
        if name not in values["_MODULES"]:
            homes.setdefault(values["_PUBLIC"][name], []).append(name)
    return homes, tuple(values["_MODULES"])


def _page(module: str, names: list[str], namespace: bool) -> str:
    if namespace:  # a module offered by name: the module and its public members
        return f"::: cassi_fit.{module}\n"
    members = "\n".join(f"        - {name}" for name in names)
    return (f"::: cassi_fit.{module}\n    options:\n      members:\n{members}\n")


def on_files(files, config):
    homes, namespaces = public_surface()
    for module in namespaces:
        homes.setdefault(module, [])
    placed = [m for _, modules in SECTIONS for m in modules]
    more = sorted(m for m in homes if m not in placed)
    nav = [{"Overview": "index.md"}]
    for title, modules in (*SECTIONS, ("More", tuple(more))):
        pages = []
        for module in modules:
            if module not in homes:
                continue
            uri = f"reference/{module}.md"
            files.append(File.generated(config, uri,
                                        content=_page(module, homes[module], module in namespaces)))
            pages.append({f"cassi_fit.{module}": uri})
        if pages:
            nav.append({title: pages})
    config["nav"] = nav
    return files
