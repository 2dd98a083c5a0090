"""cassi_fit: CASSI (Scheidt & Hamilton 1999) reproduced and extended in JAX.

A 3D Parke-style face with tongue, teeth and palate, animated from X-ray microbeam pellet
trajectories, with the jaw rotation computed by the paper's closed form or by least squares.

The public names below are imported lazily, so ``import cassi_fit`` is cheap and does not
start JAX or OpenGL until something that needs them is used.
"""

from __future__ import annotations

import importlib
import os

__version__ = "0.1.0"

# JAX on this toolkit's machines is CPU-only; keep it from probing for accelerators.
os.environ.setdefault("JAX_PLATFORMS", "cpu")

_PUBLIC = {
    # errors
    "CassiError": "errors",
    "DataFormatError": "errors",
    "MissingDataError": "errors",
    "DegenerateGeometryError": "errors",
    "OutputExistsError": "errors",
    "RenderingUnavailableError": "errors",
    # data layer
    "PELLET_NAMES": "txy",
    "PelletTrack": "txy",
    "read_txy": "txy",
    "write_txy": "txy",
    "first_valid_frame": "txy",
    "read_outline": "outlines",
    "write_outline": "outlines",
    "HeadMeasures": "headmeasures",
    "read_headmeasures": "headmeasures",
    "write_headmeasures": "headmeasures",
    "DEFAULT_HEAD_MEASURES": "headmeasures",
    "Dataset": "dataset",
    "Recording": "dataset",
    "load_recording": "dataset",
    "require_tracked": "txy",
    "DefaultHeadMeasuresWarning": "dataset",
    "QualityReport": "quality",
    "quality_report": "quality",
    "detect_mistracks": "quality",
    # synthetic corpus
    "generate_corpus": "synth",
    "load_truth": "synth",
    "load_anatomy": "synth",
    "SubjectAnatomy": "synth",
    "JawTruth": "synth",
    "make_subject": "synth",
    "synth_recording": "synth",
    "ensure_default_corpus": "synth",
    "TASKS": "synth",
    # jaw
    "closed_form": "jaw",
    "closed_form_paper": "jaw",
    "fit_jaw": "jaw_fit",
    # face model
    "FaceModel": "face_model",
    "load_model": "face_model",
    "FaceParams": "deform",
    "default_params": "deform",
    "MATERIALS": "face_model",
    "vertex_normals": "deform",
    "model_pellets": "deform",
    "build_palate": "palate",
    "with_palate": "palate",
    # pipeline
    # `deform` and `animate` are module names too; their functions are imported from
    # the modules (`from cassi_fit.deform import deform`) so that a name means one thing.
    "initialize": "animate",
    "Renderer": "render",
    # subject fitting, collisions, evaluation
    "Calibration": "calibrate",
    "calibrate_subject": "calibrate",
    "calibrate_dataset": "calibrate",
    "read_calibration": "calibrate",
    "write_calibration": "calibrate",
    "load_calibrations": "calibrate",
    "evaluate_dataset": "evaluate",
    "evaluate_recording": "evaluate",
}

__all__ = sorted(_PUBLIC) + ["rigid"]


def __getattr__(name: str):
    if name == "rigid":
        return importlib.import_module(".rigid", __name__)
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'cassi_fit' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return __all__
