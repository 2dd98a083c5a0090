"""The toolkit's Parke-style face model (with the inside of the mouth) and its loader.

The data live in the repository's ``model/`` folder, installed as the package data of
``cassi_fit.model`` (format: ``model/README.md``):
``vertices.csv`` (positions, jaw weights, deformation fields), ``faces.csv``
(triangles with a material), ``model.json`` (regions, landmarks, measures) and
``parameters.csv`` (the parameter table). Any mesh written in that format loads here.

Model frame (mm): origin at the upper incisor tip, +x to the front, +y up, +z to the
subject's left; z = 0 is the midsagittal plane, which is the XRMB pellet plane.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import importlib.resources
import io
import warnings
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jax import Array
from jaxtyping import Int

from ._io import read_json, register_input
from .errors import DataFormatError, MissingDataError

MATERIALS = ("skin", "lips", "eye", "teeth", "tongue", "palate", "pharynx")
REGIONS = ("skin", "upper_lip", "lower_lip", "jaw", "under_chin", "neck", "cheek", "nose",
           "eyes", "upper_teeth", "lower_teeth", "tongue", "palate")
LANDMARKS = ("upper_incisor_tip", "lower_incisor_tip", "MNI", "MNM", "UL", "LL", "T1", "T2",
             "T3", "T4", "gonion", "gnathion", "nose_tip", "subnasale", "mouth_corner_left",
             "mouth_corner_right", "zygion_left", "zygion_right")
MEASURES = ("face_width", "jaw_width", "mouth_width", "upper_lip_thickness",
            "lower_lip_thickness", "nose_protrusion")
# Per-vertex deformation fields stored beside the positions (see model/README.md), and
# one colour field ("hair": signed distance in mm to the edge of the hair, positive on
# it; cassi_fit.render draws the skin in the hair's colour there).
FIELDS = ("upper_lip", "lower_lip", "upper_vermilion", "lower_vermilion", "mouth", "nose",
          "nose_rise", "jaw_shape", "tongue_s", "tongue_jaw", "tongue_follow", "hair")
VERTEX_COLUMNS = ("x", "y", "z", "w_cassi", "w_parke") + FIELDS
_ONE_IF_ABSENT = ("tongue_follow",)


def _digest(value, h) -> None:
    """Feed ``value`` (numpy arrays, dicts, lists, numbers, strings) into the hash ``h``."""
    if isinstance(value, np.ndarray):
        h.update(f"{value.dtype}{value.shape}".encode())
        h.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, dict):
        for key in sorted(value, key=str):
            h.update(repr(key).encode())
            _digest(value[key], h)
    elif isinstance(value, (list, tuple)):
        h.update(f"[{len(value)}".encode())
        for item in value:
            _digest(item, h)
    else:
        h.update(repr(value).encode())


def _frozen(value):
    """``value`` with every numpy array made read-only (the digest must stay true)."""
    if isinstance(value, np.ndarray):
        value = np.array(value)
        value.setflags(write=False)
        return value
    if isinstance(value, dict):
        return {k: _frozen(v) for k, v in value.items()}
    return value


@dataclasses.dataclass(frozen=True, eq=False)
class Topology:
    """What a face model does not animate: triangles, materials, vertex sets, numbers.

    ``faces`` (F, 3) int and ``face_material`` (F,) (indices into ``MATERIALS``);
    ``regions`` name -> vertex indices; ``landmarks`` name -> vertex index; ``measures``
    name -> mm (plus ``jaw_pivot_x/y``, ``tongue_anchor_s``); ``collision`` name -> vertex
    chains along the dental arches (``cassi_fit.collide``; empty if the model has none).

    Hashable: ``__hash__`` and ``__eq__`` use ``digest``, a SHA-1 of the content computed
    once when the topology is made (its arrays are read-only). The face model keeps it as
    a static field, so ``eqx.filter_jit`` compiles once per topology *content*: two
    models loaded from the same files share every compiled function.
    """

    faces: np.ndarray
    face_material: np.ndarray
    regions: dict
    landmarks: dict
    measures: dict
    collision: dict = dataclasses.field(default_factory=dict)
    digest: str = dataclasses.field(default="", repr=False)

    def __post_init__(self):
        h = hashlib.sha1()
        for f in dataclasses.fields(self):
            if f.name != "digest":
                value = _frozen(getattr(self, f.name))
                object.__setattr__(self, f.name, value)
                h.update(f.name.encode())
                _digest(value, h)
        object.__setattr__(self, "digest", h.hexdigest())

    def __hash__(self) -> int:
        return hash(self.digest)

    def __eq__(self, other) -> bool:
        return isinstance(other, Topology) and other.digest == self.digest


class FaceModel(eqx.Module):
    """The rest mesh and everything needed to deform it.

    Arrays (traced by ``jit``): ``vertices`` (V, 3) mm; ``jaw_weights`` "cassi" and
    "parke" -> (V,) fraction of the jaw rotation; ``fields`` name -> (V,) deformation
    weights (``FIELDS``). Static: ``topology``, a hashable :class:`Topology`, whose
    parts read as attributes of the model (``faces``, ``face_material``, ``regions``,
    ``landmarks``, ``measures``, ``collision``).
    """

    vertices: Array
    jaw_weights: dict
    fields: dict
    topology: Topology = eqx.field(static=True)

    @property
    def faces(self) -> Int[np.ndarray, "f 3"]:
        return self.topology.faces

    @property
    def face_material(self) -> Int[np.ndarray, " f"]:
        return self.topology.face_material

    @property
    def regions(self) -> dict:
        return self.topology.regions

    @property
    def landmarks(self) -> dict:
        return self.topology.landmarks

    @property
    def measures(self) -> dict:
        return self.topology.measures

    @property
    def collision(self) -> dict:
        return self.topology.collision


def default_model_dir() -> Path:
    """The folder holding the toolkit's own face model (``vertices.csv``, ``model.json`` ...).

    Installed (wheel, ``pip install .``, editable), the files are the package data of
    ``cassi_fit.model`` (the checkout's ``model/`` folder, mapped by pyproject.toml) and are
    found through ``importlib.resources``. From a source checkout that is merely on
    ``sys.path`` that subpackage does not exist, and the checkout's ``model/`` is used.
    """
    try:
        root = importlib.resources.files("cassi_fit.model")
    except ModuleNotFoundError as exc:
        if exc.name != "cassi_fit.model":
            raise
        return Path(__file__).resolve().parents[1] / "model"
    if not isinstance(root, Path):  # e.g. a zipped install: the loader needs real files
        raise MissingDataError(f"{root}: the face model must be installed as files, not zipped")
    return root


def _read_table(path: Path, columns, optional=()) -> tuple[np.ndarray, list[str]]:
    """A CSV with a header naming at least ``columns``, read once: ``(rows, found)``, the
    float rows (n, len(columns) + len(found)) of ``columns`` followed by the ``optional``
    columns the header names (``found``, in the order of ``optional``)."""
    if not path.exists():
        raise MissingDataError(f"{path}: model file not found")
    register_input(path)
    with open(path, newline="", encoding="utf-8") as fh:
        text = fh.read()
    header = [h.strip() for h in next(csv.reader([text.partition("\n")[0]]), [])]
    missing = [c for c in columns if c not in header]
    if missing:
        raise DataFormatError(path, 1, f"header lacks column(s) {', '.join(missing)}")
    found = [c for c in optional if c in header]
    pick = [header.index(c) for c in (*columns, *found)]
    try:  # numpy's parser (C): the same doubles as float() on the same text
        with warnings.catch_warnings():  # no rows: said below, with the file's name
            warnings.simplefilter("ignore")
            rows = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, usecols=pick,
                              ndmin=2, comments=None, dtype=float)
        if len(rows) and np.all(np.isfinite(rows)):
            return rows, found
    except ValueError:
        pass
    return _read_rows(path, text, header, pick), found  # row by row: what is wrong where


def _read_rows(path: Path, text: str, header: list[str], pick: list[int]) -> np.ndarray:
    """The columns ``pick`` of a CSV's rows parsed one by one, each error with its line."""
    rows = []
    for line, row in enumerate(csv.reader(io.StringIO(text, newline="")), start=1):
        if line == 1 or not row or all(not c.strip() for c in row):
            continue
        try:
            values = [float(row[k]) for k in pick]
        except (ValueError, IndexError):
            raise DataFormatError(
                path, line, f"expected {len(header)} numbers, got {row!r}") from None
        if not np.all(np.isfinite(values)):
            raise DataFormatError(path, line, "non-finite value")
        rows.append(values)
    if not rows:
        raise DataFormatError(path, None, "no data rows")
    return np.array(rows)


def _check_index(path, what, index, n):
    index = np.asarray(index, dtype=np.int64)
    if index.size and (index.min() < 0 or index.max() >= n):
        raise DataFormatError(path, None, f"{what} refers to vertex {index.max()} of {n}")
    return index


def load_model(path: str | Path | None = None) -> FaceModel:
    """Load a model folder (default: the repository's ``model/``) as a :class:`FaceModel`."""
    folder = Path(path) if path is not None else default_model_dir()
    vpath, fpath, mpath = folder / "vertices.csv", folder / "faces.csv", folder / "model.json"
    required = ("x", "y", "z", "w_cassi", "w_parke")
    table, extra = _read_table(vpath, required, optional=FIELDS)
    fields_table = table[:, len(required):]
    n = len(table)
    ftable, _ = _read_table(fpath, ("a", "b", "c", "material"))
    faces = _check_index(fpath, "a face", ftable[:, :3].astype(np.int64), n)
    material = ftable[:, 3].astype(np.int64)
    if material.min() < 0 or material.max() >= len(MATERIALS):
        raise DataFormatError(fpath, None, f"material index outside 0..{len(MATERIALS) - 1}")
    meta = read_json(mpath, "model file")
    for key in ("regions", "landmarks", "measures"):
        if key not in meta:
            raise DataFormatError(mpath, None, f"missing the {key!r} entry")
    regions = {k: _check_index(mpath, f"region {k}", v, n) for k, v in meta["regions"].items()}
    for name in REGIONS:
        regions.setdefault(name, np.zeros(0, dtype=np.int64))
    landmarks = {k: int(v) for k, v in meta["landmarks"].items()}
    for k, v in landmarks.items():
        _check_index(mpath, f"landmark {k}", [v], n)
    collision = {}
    for k, v in meta.get("collision", {}).items():
        index = np.asarray(v, dtype=np.int64)
        collision[k] = index if k.endswith("_tooth") else _check_index(mpath, f"chain {k}", v, n)
        if k.endswith("_columns") and index.ndim != 2:
            raise DataFormatError(mpath, None, f"collision {k} must be a list of columns")
    vertices = jnp.asarray(table[:, :3])
    fields = {f: jnp.asarray(fields_table[:, k]) for k, f in enumerate(extra)}
    for f in FIELDS:  # absent: 0, but the tongue follows its pellets whole (no floor)
        fields.setdefault(f, jnp.ones(n) if f in _ONE_IF_ABSENT else jnp.zeros(n))
    topology = Topology(
        faces=faces,
        face_material=material,
        regions=regions,
        landmarks=landmarks,
        measures={k: float(v) for k, v in meta["measures"].items()},
        collision=collision,
    )
    return FaceModel(
        vertices=vertices,
        jaw_weights={"cassi": jnp.asarray(table[:, 3]), "parke": jnp.asarray(table[:, 4])},
        fields=fields,
        topology=topology,
    )
