"""cassi_fit: CASSI (Scheidt & Hamilton 1999) reproduced and extended in JAX.

A 3D Parke-style face with tongue, teeth and palate, animated from X-ray microbeam pellet
trajectories, with the jaw rotation computed by the paper's closed form or by least squares.

This module is the one public surface: everything the README and the notebooks use is
importable from ``cassi_fit`` and listed in ``__all__``. The names are imported lazily
(``_PUBLIC`` says from where), so ``import cassi_fit`` is cheap and neither starts JAX or
OpenGL nor changes the environment (JAX's platform is the user's choice; the ``cassi``
command picks the CPU for itself). The ``TYPE_CHECKING`` block states the same imports in
``from ._x import Y as Y`` form for type checkers and readers; tests/test_public_api.py
keeps the two in step.

``animate``, ``deform`` and ``synth`` are modules (a name means one thing: the function
``animate`` is ``cassi_fit.animate.animate``), as is ``rigid``.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING

__version__ = "0.1.0"

if TYPE_CHECKING:
    from . import animate as animate
    from . import deform as deform
    from . import rigid as rigid
    from . import synth as synth
    from .acoustic_fit import fit_tract as fit_tract
    from .acoustics import Acoustics as Acoustics
    from .acoustics import SpeakerNorms as SpeakerNorms
    from .acoustics import plot_acoustics as plot_acoustics
    from .acoustics import recording_acoustics as recording_acoustics
    from .acoustics import speaker_norms as speaker_norms
    from .animate import Animation as Animation
    from .area_function import TractParams as TractParams
    from .area_function import tract_geometry as tract_geometry
    from .calibrate import calibrate_dataset as calibrate_dataset
    from .calibrate import calibrate_subject as calibrate_subject
    from .calibrate_corpus import calibrate_corpus as calibrate_corpus
    from .calibration import Calibration as Calibration
    from .calibration import CalibrationWarning as CalibrationWarning
    from .calibration import load_calibrations as load_calibrations
    from .calibration import read_calibration as read_calibration
    from .calibration import write_calibration as write_calibration
    from .corpus import CorpusItem as CorpusItem
    from .corpus import CorpusRun as CorpusRun
    from .corpus import dataset_items as dataset_items
    from .corpus import run_corpus as run_corpus
    from .dataset import Dataset as Dataset
    from .dataset import DefaultHeadMeasuresWarning as DefaultHeadMeasuresWarning
    from .dataset import Recording as Recording
    from .dataset import SpecialFileWarning as SpecialFileWarning
    from .dataset import load_recording as load_recording
    from .dataset import recording_from_array as recording_from_array
    from .deform import FaceParams as FaceParams
    from .deform import default_params as default_params
    from .deform import model_pellets as model_pellets
    from .deform import vertex_normals as vertex_normals
    from .ema import SensorReport as SensorReport
    from .ema.synthetic import write_ema_corpus as write_ema_corpus
    from .errors import CassiError as CassiError
    from .errors import DataFormatError as DataFormatError
    from .errors import DegenerateGeometryError as DegenerateGeometryError
    from .errors import InvalidChoiceError as InvalidChoiceError
    from .errors import MissingDataError as MissingDataError
    from .errors import OutputExistsError as OutputExistsError
    from .errors import RenderingUnavailableError as RenderingUnavailableError
    from .evaluate import EvaluationResult as EvaluationResult
    from .evaluate import compare as compare
    from .evaluate import evaluate_corpus as evaluate_corpus
    from .evaluate import evaluate_dataset as evaluate_dataset
    from .evaluate import evaluate_recording as evaluate_recording
    from .evaluate import write_report as write_report
    from .evaluate import write_table as write_table
    from .face_model import MATERIALS as MATERIALS
    from .face_model import FaceModel as FaceModel
    from .face_model import Topology as Topology
    from .face_model import load_model as load_model
    from .formant_track import FormantTrack as FormantTrack
    from .formant_track import measure_formants as measure_formants
    from .gaps import repair as repair
    from .headmeasures import DEFAULT_HEAD_MEASURES as DEFAULT_HEAD_MEASURES
    from .headmeasures import HeadMeasures as HeadMeasures
    from .headmeasures import read_headmeasures as read_headmeasures
    from .headmeasures import write_headmeasures as write_headmeasures
    from .initialize import SubjectState as SubjectState
    from .initialize import initialize as initialize
    from .jaw import closed_form as closed_form
    from .jaw import closed_form_paper as closed_form_paper
    from .jaw_fit import ClosedForm as ClosedForm
    from .jaw_fit import CoupledRotation as CoupledRotation
    from .jaw_fit import Dogleg as Dogleg
    from .jaw_fit import FixedPivot as FixedPivot
    from .jaw_fit import FrameFit as FrameFit
    from .jaw_fit import GaussNewton as GaussNewton
    from .jaw_fit import JawCoupling as JawCoupling
    from .jaw_fit import JawDiagnostics as JawDiagnostics
    from .jaw_fit import JawFit as JawFit
    from .jaw_fit import JawMethod as JawMethod
    from .jaw_fit import LevenbergMarquardt as LevenbergMarquardt
    from .jaw_fit import PivotPrior as PivotPrior
    from .jaw_fit import SmoothPivot as SmoothPivot
    from .jaw_fit import Solver as Solver
    from .jaw_fit import fit_jaw as fit_jaw
    from .jaw_fit import jaw_diagnostics as jaw_diagnostics
    from .jaw_fit import jaw_from_track as jaw_from_track
    from .jaw_fit import jaw_method as jaw_method
    from .jaw_fit import jaw_solver as jaw_solver
    from .jaw_fit import learn_jaw_coupling as learn_jaw_coupling
    from .jaw_table import jaw_corpus as jaw_corpus
    from .labels import Labels as Labels
    from .labels import labels_for as labels_for
    from .labels import read_lab as read_lab
    from .labels import read_labels as read_labels
    from .labels import read_textgrid as read_textgrid
    from .labels import segment_summary as segment_summary
    from .labels import write_lab as write_lab
    from .labels import write_textgrid as write_textgrid
    from .mistracks import MistrackReport as MistrackReport
    from .mistracks import detect_mistracks as detect_mistracks
    from .mistracks import mistrack_report as mistrack_report
    from .options import JAW_METHODS as JAW_METHODS
    from .options import SOLVERS as SOLVERS
    from .outlines import read_outline as read_outline
    from .outlines import write_outline as write_outline
    from .palate import build_palate as build_palate
    from .palate import with_palate as with_palate
    from .pellets import JAW_PELLETS as JAW_PELLETS
    from .pellets import PELLET_NAMES as PELLET_NAMES
    from .pellets import MistrackedFirstLineWarning as MistrackedFirstLineWarning
    from .pellets import first_valid_line as first_valid_line
    from .pellets import pellet_index as pellet_index
    from .pharynx import build_pharynx as build_pharynx
    from .pharynx import with_pharynx as with_pharynx
    from .pipeline import RecordingRun as RecordingRun
    from .pipeline import run_recording as run_recording
    from .quality import QualityReport as QualityReport
    from .quality import quality_report as quality_report
    from .recording_video import animate_corpus as animate_corpus
    from .recording_video import subject_traces as subject_traces
    from .recording_video import write_animation as write_animation
    from .recording_video import write_recording_video as write_recording_video
    from .render import Renderer as Renderer
    from .render import midsagittal_figure as midsagittal_figure
    from .reports import jaw_comparison_plot as jaw_comparison_plot
    from .reports import write_penetration_csv as write_penetration_csv
    from .run_spec import CalibrationFiles as CalibrationFiles
    from .run_spec import RunSpec as RunSpec
    from .run_spec import run_spec as run_spec
    from .status import SolverResult as SolverResult
    from .status import Status as Status
    from .synth import TASKS as TASKS
    from .synth import JawTruth as JawTruth
    from .synth import SubjectAnatomy as SubjectAnatomy
    from .synth import ensure_default_corpus as ensure_default_corpus
    from .synth import generate_corpus as generate_corpus
    from .synth import load_anatomy as load_anatomy
    from .synth import load_truth as load_truth
    from .synth import make_subject as make_subject
    from .synth import synth_recording as synth_recording
    from .tongue import tongue_volume as tongue_volume
    from .tongue import tongue_volumes as tongue_volumes
    from .tube import formants as formants
    from .txy import PelletTrack as PelletTrack
    from .txy import TimeGapWarning as TimeGapWarning
    from .txy import read_txy as read_txy
    from .txy import require_tracked as require_tracked
    from .txy import write_txy as write_txy
    from .viewer import ViewerPage as ViewerPage
    from .viewer import view as view
    from .viewer import write_view as write_view

_PUBLIC = {
    # errors (base)
    "CassiError": "errors",
    "DataFormatError": "errors",
    "MissingDataError": "errors",
    "DegenerateGeometryError": "errors",
    "OutputExistsError": "errors",
    "RenderingUnavailableError": "errors",
    "InvalidChoiceError": "errors",
    # status (base)
    "Status": "status",
    "SolverResult": "status",
    # options (base)
    "JAW_METHODS": "options",
    "SOLVERS": "options",
    # pellets (data)
    "PELLET_NAMES": "pellets",
    "JAW_PELLETS": "pellets",
    "pellet_index": "pellets",
    "first_valid_line": "pellets",
    "MistrackedFirstLineWarning": "pellets",
    # txy (data)
    "PelletTrack": "txy",
    "read_txy": "txy",
    "write_txy": "txy",
    "require_tracked": "txy",
    "TimeGapWarning": "txy",
    # outlines (data)
    "read_outline": "outlines",
    "write_outline": "outlines",
    # headmeasures (data)
    "HeadMeasures": "headmeasures",
    "read_headmeasures": "headmeasures",
    "write_headmeasures": "headmeasures",
    "DEFAULT_HEAD_MEASURES": "headmeasures",
    # dataset (data)
    "Dataset": "dataset",
    "Recording": "dataset",
    "load_recording": "dataset",
    "recording_from_array": "dataset",
    "write_ema_corpus": "ema.synthetic",
    "DefaultHeadMeasuresWarning": "dataset",
    "SpecialFileWarning": "dataset",
    # ema (data): articulograph files
    "SensorReport": "ema",
    # quality (data)
    "QualityReport": "quality",
    "quality_report": "quality",
    # mistracks (data)
    "detect_mistracks": "mistracks",  # its home (quality uses it)
    "MistrackReport": "mistracks",
    "mistrack_report": "mistracks",
    # gaps (data)
    "repair": "gaps",
    # labels (data)
    "Labels": "labels",
    "read_labels": "labels",
    "read_lab": "labels",
    "read_textgrid": "labels",
    "write_lab": "labels",
    "write_textgrid": "labels",
    "labels_for": "labels",
    "segment_summary": "labels",
    # synth (synthetic corpus)
    "generate_corpus": "synth",
    "load_truth": "synth",
    "load_anatomy": "synth",
    "SubjectAnatomy": "synth",
    "JawTruth": "synth",
    "make_subject": "synth",
    "synth_recording": "synth",
    "ensure_default_corpus": "synth",
    "TASKS": "synth",
    # face_model (model)
    "FaceModel": "face_model",
    "Topology": "face_model",
    "load_model": "face_model",
    "MATERIALS": "face_model",
    # deform (model)
    "FaceParams": "deform",
    "default_params": "deform",
    "vertex_normals": "deform",
    # tongue (model)
    "tongue_volume": "tongue",
    "tongue_volumes": "tongue",
    "model_pellets": "deform",
    # palate (model)
    "build_palate": "palate",
    "with_palate": "palate",
    "build_pharynx": "pharynx",
    "with_pharynx": "pharynx",
    # jaw (fitting)
    "closed_form": "jaw",
    "closed_form_paper": "jaw",
    # jaw_fit (fitting)
    "fit_jaw": "jaw_fit",
    "jaw_from_track": "jaw_fit",
    "JawFit": "jaw_fit",
    "ClosedForm": "jaw_fit",
    "FrameFit": "jaw_fit",
    "FixedPivot": "jaw_fit",
    "SmoothPivot": "jaw_fit",
    "JawMethod": "jaw_fit",
    "jaw_method": "jaw_fit",
    "jaw_solver": "jaw_fit",
    "LevenbergMarquardt": "jaw_fit",
    "GaussNewton": "jaw_fit",
    "Dogleg": "jaw_fit",
    "Solver": "jaw_fit",
    "jaw_diagnostics": "jaw_fit",
    "JawDiagnostics": "jaw_fit",
    "CoupledRotation": "jaw_fit",
    "PivotPrior": "jaw_fit",
    "JawCoupling": "jaw_fit",
    "learn_jaw_coupling": "jaw_fit",
    # the vocal tract heard (issue 29): area function, tube, measured formants, calibration
    "TractParams": "area_function",
    "tract_geometry": "area_function",
    "formants": "tube",
    "FormantTrack": "formant_track",
    "measure_formants": "formant_track",
    "fit_tract": "acoustic_fit",
    "Acoustics": "acoustics",
    "recording_acoustics": "acoustics",
    "plot_acoustics": "acoustics",
    "SpeakerNorms": "acoustics",
    "speaker_norms": "acoustics",
    # calibration (fitting): the record and its file
    "Calibration": "calibration",
    "CalibrationWarning": "calibration",
    "read_calibration": "calibration",
    "write_calibration": "calibration",
    "load_calibrations": "calibration",
    # calibrate (fitting)
    "calibrate_subject": "calibrate",
    "calibrate_dataset": "calibrate",
    # initialize (pipeline)
    "initialize": "initialize",
    "SubjectState": "initialize",
    # run_spec and pipeline: one run's every choice, and the one runner
    "RunSpec": "run_spec",
    "run_spec": "run_spec",
    "CalibrationFiles": "run_spec",
    "run_recording": "pipeline",
    "RecordingRun": "pipeline",
    # animate (pipeline)
    "Animation": "animate",
    # render (outputs)
    "Renderer": "render",
    "midsagittal_figure": "render",
    # video (outputs)
    "write_animation": "recording_video",
    "write_recording_video": "recording_video",
    "view": "viewer",
    "write_view": "viewer",
    "ViewerPage": "viewer",
    "subject_traces": "recording_video",
    # reports (outputs)
    "write_penetration_csv": "reports",
    "jaw_comparison_plot": "reports",
    # evaluate (outputs)
    "evaluate_dataset": "evaluate",
    "evaluate_recording": "evaluate",
    "EvaluationResult": "evaluate",
    "write_table": "evaluate",
    "write_report": "evaluate",
    "compare": "evaluate",
    # corpus (runs)
    "run_corpus": "corpus",
    "jaw_corpus": "jaw_table",
    "evaluate_corpus": "evaluate",
    "calibrate_corpus": "calibrate_corpus",
    "animate_corpus": "recording_video",
    "dataset_items": "corpus",
    "CorpusItem": "corpus",
    "CorpusRun": "corpus",
}
# Submodules offered as namespaces (their names are modules, never functions).
_MODULES = ("animate", "deform", "rigid", "synth")

__all__ = [
    "Animation", "Calibration", "CalibrationWarning", "CassiError", "ClosedForm", "CorpusItem",
    "CorpusRun", "CoupledRotation", "JawCoupling", "PivotPrior", "learn_jaw_coupling",
    "DEFAULT_HEAD_MEASURES", "DataFormatError", "Dataset", "DefaultHeadMeasuresWarning",
    "DegenerateGeometryError", "Dogleg", "EvaluationResult", "FaceModel", "FaceParams",
    "FixedPivot", "FrameFit", "GaussNewton", "HeadMeasures", "InvalidChoiceError", "JAW_METHODS",
    "JAW_PELLETS", "JawDiagnostics", "JawFit", "JawMethod", "JawTruth", "Labels",
    "LevenbergMarquardt", "MATERIALS", "MissingDataError", "MistrackReport",
    "MistrackedFirstLineWarning",
    "OutputExistsError", "PELLET_NAMES", "PelletTrack", "QualityReport", "Recording", "Renderer",
    "RenderingUnavailableError", "SOLVERS", "SmoothPivot", "Solver", "SolverResult", "Status",
    "SpecialFileWarning", "SubjectAnatomy", "SubjectState", "TASKS", "TimeGapWarning",
    "Topology", "animate",
    "animate_corpus", "build_palate", "calibrate_corpus", "calibrate_dataset",
    "calibrate_subject", "closed_form", "closed_form_paper", "compare",
    "dataset_items", "default_params", "deform", "detect_mistracks", "ensure_default_corpus",
    "evaluate_corpus", "evaluate_dataset", "evaluate_recording", "first_valid_line", "fit_jaw",
    "generate_corpus", "initialize",
    "jaw_comparison_plot", "jaw_corpus", "jaw_diagnostics", "jaw_from_track", "jaw_method",
    "jaw_solver", "labels_for", "load_anatomy", "load_calibrations", "load_model",
    "load_recording", "load_truth", "make_subject", "midsagittal_figure", "mistrack_report",
    "model_pellets", "pellet_index",
    "quality_report", "read_calibration", "read_headmeasures", "read_lab", "read_labels",
    "read_outline", "read_textgrid", "read_txy", "recording_from_array", "write_ema_corpus", "repair",
    "require_tracked", "rigid", "SensorReport",
    "run_corpus", "segment_summary", "subject_traces", "synth", "synth_recording",
    "tongue_volume", "tongue_volumes", "vertex_normals", "with_palate", "build_pharynx",
    "with_pharynx",
    "RunSpec", "run_spec", "CalibrationFiles", "run_recording", "RecordingRun",
    "write_recording_video",
    "view", "write_view", "ViewerPage",
    "Acoustics", "FormantTrack", "TractParams", "fit_tract", "formants", "measure_formants",
    "plot_acoustics", "recording_acoustics", "tract_geometry", "SpeakerNorms", "speaker_norms",
    "write_animation", "write_calibration", "write_headmeasures", "write_lab", "write_outline",
    "write_penetration_csv", "write_report", "write_table", "write_textgrid", "write_txy",
]


def __getattr__(name: str) -> object:
    if name in _MODULES:
        return importlib.import_module(f".{name}", __name__)
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'cassi_fit' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return list(__all__)


class _PublicSurface(types.ModuleType):
    """The package's module type. Importing a submodule binds it to the package under its
    own name, so the public functions named as their modules (``initialize``, ``run_spec``,
    ``jaw_corpus``, ``calibrate_corpus``) would turn into modules as soon as anything
    imported those (``from cassi_fit import run_recording, initialize`` gave the module
    ``initialize``). Such a binding is refused here: the name keeps meaning the function.
    ``sys.modules`` still holds the module: ``from cassi_fit.initialize import ...`` and
    ``importlib.import_module`` work as ever (``import cassi_fit.initialize as m``, which
    reads the package's attribute, gives the function)."""

    def __setattr__(self, name: str, value: object) -> None:
        if (name in _PUBLIC and isinstance(value, types.ModuleType)
                and value.__name__ == f"{__name__}.{name}"):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _PublicSurface
