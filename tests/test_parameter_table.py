"""model/parameters.csv agrees with FaceParams: every parameter listed, defaults neutral."""

import csv
from pathlib import Path

import numpy as np

from cassi_fit.deform import default_params

TABLE = Path(__file__).resolve().parents[1] / "model" / "parameters.csv"
KINDS = {"interpolation", "rotation", "scale", "translation"}


def _rows():
    with TABLE.open(newline="") as fh:
        return list(csv.DictReader(fh))


def _flat_defaults():
    """FaceParams flattened to the table's names (vector fields get _x/_y or T1_X ...)."""
    p = default_params()
    flat = {}
    for name in type(p).__dataclass_fields__:
        value = np.asarray(getattr(p, name))
        if value.ndim == 0:
            flat[name] = float(value)
        elif name == "tongue":
            for i, site in enumerate(("T1", "T2", "T3", "T4")):
                flat[f"{site}_X"], flat[f"{site}_Z"] = map(float, value[i])
        elif name in ("upper_lip", "lower_lip"):
            flat[f"{name}_X"], flat[f"{name}_Z"] = map(float, value)
        else:
            flat[f"{name}_x"], flat[f"{name}_y"] = map(float, value)
    return flat


def test_every_parameter_is_in_the_table_with_its_neutral_default():
    rows = {r["name"]: r for r in _rows()}
    defaults = _flat_defaults()
    assert set(rows) == set(defaults)
    for name, value in defaults.items():
        row = rows[name]
        assert float(row["default"]) == value, name
        assert float(row["min"]) <= value <= float(row["max"]), name
        assert row["kind"] in KINDS, name
        assert row["stored_positions"], name


def test_cassi_parameters_are_numbered_as_in_the_paper():
    numbers = {r["number"]: r["name"] for r in _rows()}
    expected = ["T1_X", "T1_Z", "T2_X", "T2_Z", "T3_X", "T3_Z", "T4_X", "T4_Z",
                "upper_lip_X", "upper_lip_Z", "lower_lip_X", "lower_lip_Z"]
    assert [numbers[str(n)] for n in range(55, 67)] == expected  # Table 1 of the paper
