"""The objective evaluation: CASSI's Table 2 ratings from measured quantities.

CASSI (Scheidt & Hamilton 1999, section 4, Table 2) rated each subject's animation by eye:
teeth, lips and tongue each EXCELLENT, VERY GOOD, GOOD or FAIR by the number of problems
seen (0, 1, 2, 3 or more). Here every problem is a measured quantity with a documented
threshold (``docs/EVALUATION.md``), and the ratings follow the same counting rule.

Pipeline: :func:`measure` (one animation -> floats; ``_measures``), :func:`problems`
(floats -> the problems counted, per component), :func:`rating` (a count -> a word) and
:func:`rate` (both; ``_ratings``); :func:`evaluate_recording` and :func:`evaluate_dataset`
run the animation and aggregate per subject into :class:`RecordingRow` and
:class:`SubjectRow` records (``_run``, ``_rows``); :func:`write_table`,
:func:`markdown_table`, :func:`plot_summary` and :func:`compare` write the results
(Markdown in Table 2's layout, CSV, a figure; ``_report``).
"""

from ._measures import AIRWAY_CLOSED_MM as AIRWAY_CLOSED_MM
from ._measures import MEASURES as MEASURES
from ._measures import SUSTAIN_S as SUSTAIN_S
from ._measures import MeasureSpec as MeasureSpec
from ._measures import airway_of as airway_of
from ._measures import combine as combine
from ._measures import measure as measure
from ._measures import penetration_of as penetration_of
from ._measures import sustain_frames as sustain_frames
from ._measures import sustained_max as sustained_max
from ._measures import sustained_min as sustained_min
from ._ratings import BACK_OVERLAP_MM as BACK_OVERLAP_MM
from ._ratings import CASSI_TOTALS as CASSI_TOTALS
from ._ratings import COMPONENTS as COMPONENTS
from ._ratings import FRONT_OVERLAP_MM as FRONT_OVERLAP_MM
from ._ratings import LIP_APART_LARGE_MM as LIP_APART_LARGE_MM
from ._ratings import LIP_APART_MM as LIP_APART_MM
from ._ratings import LIP_BEYOND_TEETH_MM as LIP_BEYOND_TEETH_MM
from ._ratings import LIP_PROTRUSION_MM as LIP_PROTRUSION_MM
from ._ratings import LIP_TIGHT_MM as LIP_TIGHT_MM
from ._ratings import PALATE_BELOW_MM as PALATE_BELOW_MM
from ._ratings import RATINGS as RATINGS
from ._ratings import SLOPE_DOWN_DEG as SLOPE_DOWN_DEG
from ._ratings import SLOPE_STEEP_DEG as SLOPE_STEEP_DEG
from ._ratings import SLOPE_UP_DEG as SLOPE_UP_DEG
from ._ratings import SLOPE_VERY_STEEP_DEG as SLOPE_VERY_STEEP_DEG
from ._ratings import TEETH_APART_MM as TEETH_APART_MM
from ._ratings import TEETH_IN_LIPS_MM as TEETH_IN_LIPS_MM
from ._ratings import TONGUE_HIDDEN_MM as TONGUE_HIDDEN_MM
from ._ratings import TONGUE_PALATE_MM as TONGUE_PALATE_MM
from ._ratings import TONGUE_POKE_DEEP_MM as TONGUE_POKE_DEEP_MM
from ._ratings import TONGUE_POKE_MM as TONGUE_POKE_MM
from ._ratings import TONGUE_V_DEG as TONGUE_V_DEG
from ._ratings import describe as describe
from ._ratings import problems as problems
from ._ratings import rate as rate
from ._ratings import rating as rating
from ._report import OUTPUT_NAMES as OUTPUT_NAMES
from ._report import SUMMARY_NAME as SUMMARY_NAME
from ._report import compare as compare
from ._report import markdown_table as markdown_table
from ._report import plot_summary as plot_summary
from ._report import write_report as write_report
from ._report import write_table as write_table
from ._rows import NO_RECORDING as NO_RECORDING
from ._rows import EvaluationResult as EvaluationResult
from ._rows import RecordingRow as RecordingRow
from ._rows import SubjectRow as SubjectRow
from ._run import MEASURE_PREFIX as MEASURE_PREFIX
from ._run import evaluate_corpus as evaluate_corpus
from ._run import evaluate_dataset as evaluate_dataset
from ._run import evaluate_recording as evaluate_recording
from ._run import evaluate_task as evaluate_task
from ._run import evaluation_result as evaluation_result

__all__ = [
    "BACK_OVERLAP_MM", "CASSI_TOTALS", "COMPONENTS", "FRONT_OVERLAP_MM", "LIP_APART_LARGE_MM",
    "LIP_APART_MM", "LIP_BEYOND_TEETH_MM", "LIP_PROTRUSION_MM", "LIP_TIGHT_MM", "MEASURES",
    "NO_RECORDING", "OUTPUT_NAMES", "PALATE_BELOW_MM", "RATINGS", "SLOPE_DOWN_DEG",
    "SLOPE_STEEP_DEG", "SLOPE_UP_DEG", "SLOPE_VERY_STEEP_DEG", "SUSTAIN_S", "TEETH_APART_MM",
    "TEETH_IN_LIPS_MM", "TONGUE_HIDDEN_MM", "TONGUE_PALATE_MM", "TONGUE_POKE_DEEP_MM",
    "TONGUE_POKE_MM", "TONGUE_V_DEG", "AIRWAY_CLOSED_MM", "airway_of", "EvaluationResult", "MeasureSpec", "RecordingRow", "SubjectRow",
    "combine", "compare", "describe", "evaluate_corpus", "evaluate_dataset",
    "evaluate_recording", "evaluate_task", "evaluation_result", "MEASURE_PREFIX",
    "markdown_table", "measure", "penetration_of", "plot_summary", "problems", "rate",
    "rating", "sustain_frames", "sustained_max", "sustained_min", "write_report", "write_table", "SUMMARY_NAME",
]  # fmt: skip
