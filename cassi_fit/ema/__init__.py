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
"""

from ._raw import RawEma
from .detect import EMA_FORMATS, detect_format, read_ema
from .report import SensorReport
from .sensor_map import SensorMap, builtin_map, read_sensor_map
from .track import ema_to_track

__all__ = ["EMA_FORMATS", "RawEma", "SensorMap", "SensorReport", "builtin_map",
           "detect_format", "ema_to_track", "read_ema", "read_sensor_map"]
