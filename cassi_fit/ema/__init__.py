"""Articulograph (EMA) data: readers, sensor maps, head correction, the occlusal frame.

One module per format family (:mod:`~cassi_fit.ema.est` EST Track files of MOCHA-TIMIT and
mngu0, :mod:`~cassi_fit.ema.carstens` Carstens AG500/AG501 ``.pos``,
:mod:`~cassi_fit.ema.wave` NDI Wave exports, :mod:`~cassi_fit.ema.mview` Haskins mview
``.mat``, :mod:`~cassi_fit.ema.arrays` numpy arrays and CSV), each returning a
:class:`~cassi_fit.ema._raw.RawEma` in the file's own frame; :mod:`~cassi_fit.ema.sensor_map`
says which sensor plays which role; :mod:`~cassi_fit.ema.head` removes head movement and
finds the occlusal frame; :mod:`~cassi_fit.ema.track` makes the pipeline's
:class:`~cassi_fit.txy.PelletTrack` with a :class:`~cassi_fit.ema.report.SensorReport`;
:mod:`~cassi_fit.ema.detect` tells the formats apart by content; :mod:`~cassi_fit.ema.synthetic`
writes the synthetic EMA corpus. The pipeline itself reads a
:class:`~cassi_fit.dataset.Recording` (``cassi_fit.dataset.load_recording``). See
docs/EMA.md.

The package's names are imported on first use (:func:`__getattr__`): loading a pellet
file (.txy, ``cassi_fit.dataset``) imports none of the readers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cassi_fit._lazy import lazy_names

if TYPE_CHECKING:
    from ._raw import RawEma as RawEma
    from .detect import EMA_FORMATS as EMA_FORMATS
    from .detect import detect_format as detect_format
    from .detect import read_ema as read_ema
    from .report import SensorReport as SensorReport
    from .sensor_map import SensorMap as SensorMap
    from .sensor_map import builtin_map as builtin_map
    from .sensor_map import read_sensor_map as read_sensor_map
    from .track import ema_to_track as ema_to_track

#: Each public name -> the module (relative to this package) it comes from.
_NAMES = {
    "RawEma": "._raw",
    "EMA_FORMATS": ".detect",
    "detect_format": ".detect",
    "read_ema": ".detect",
    "SensorReport": ".report",
    "SensorMap": ".sensor_map",
    "builtin_map": ".sensor_map",
    "read_sensor_map": ".sensor_map",
    "ema_to_track": ".track",
}

__all__ = ["EMA_FORMATS", "RawEma", "SensorMap", "SensorReport", "builtin_map",
           "detect_format", "ema_to_track", "read_ema", "read_sensor_map"]


__getattr__, __dir__ = lazy_names(__name__, _NAMES, globals())
