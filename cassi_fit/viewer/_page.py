"""The one-file viewer page: :func:`view` (Python, inline in Jupyter), :class:`ViewerPage`
and :func:`write_view` (``cassi view RECORDING --out talk.html``).

The page is one HTML file that works offline from a ``file://`` URL: the data
(:mod:`cassi_fit.viewer._data`) in a JSON block, the sound as a base64 ``data:`` URL, and
one inline script (``assets/viewer.js``: the page's code with three.js, bundled by esbuild
from ``viewer_js/``; module scripts are blocked on ``file://``, so nothing is a module and
nothing is fetched).
"""

from __future__ import annotations

import base64
import html
import json
import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from ._data import page_data

_PARTS = (("teeth", "teeth"), ("tongue", "tongue"), ("palate", "palate"),
          ("pharynx", "pharyngeal wall"))  # fmt: skip
_VIEW_LABELS = (("front", "front"), ("side", "side"), ("inside", "inside"), ("top", "top"))
IFRAME_HEIGHT_PX = 900


def _asset(name: str) -> str:
    return resources.files("cassi_fit.viewer").joinpath("assets", name).read_text("utf-8")


_STYLE = """
body { font: 14px system-ui, sans-serif; margin: 8px 12px; color: #222; background: #fafafa; }
h1 { font-size: 18px; margin: 0 0 2px; } header p { margin: 0 0 6px; color: #444; }
#cassi-main { display: flex; gap: 8px; height: 460px; }
#cassi-view { flex: 3; position: relative; min-width: 0; }
#cassi-3d { width: 100%; height: 100%; display: block; background: #ebebeb; }
#cassi-section { flex: 2; min-width: 0; height: 100%; background: #fff; border: 1px solid #ccc; }
#cassi-nogl { display: none; padding: 24px; background: #fee; border: 1px solid #c99; }
#cassi-controls, #cassi-options { display: flex; gap: 8px; align-items: center;
  margin: 6px 0; flex-wrap: wrap; }
#cassi-scrub { flex: 1; min-width: 200px; }
#cassi-clock { font-family: monospace; white-space: pre; min-width: 30em; }
button.on { background: #2a5db0; color: #fff; }
.cassi-tier { display: flex; height: 22px; margin: 2px 0; }
.cassi-tier-name { width: 60px; font-size: 11px; color: #555; }
.cassi-track { position: relative; flex: 1; background: #f0f0f0; }
.cassi-label { position: absolute; top: 0; bottom: 0; border-left: 1px solid #888;
  font-size: 11px; overflow: hidden; cursor: pointer; text-align: center; line-height: 22px; }
.cassi-label:hover { background: #dde6f5; } .cassi-label.on { background: #c9d8f3; }
.cassi-cursor { position: absolute; top: 0; bottom: 0; width: 2px; background: #d11;
  pointer-events: none; }
#cassi-plots { display: flex; gap: 8px; height: 110px; }
#cassi-plots canvas { flex: 1; min-width: 0; height: 100%; border: 1px solid #ccc; }
footer { color: #666; font-size: 12px; margin-top: 6px; }
"""


def _controls() -> str:
    presets = "".join(f'<button data-preset="{v}">{t}</button>' for v, t in _VIEW_LABELS)
    parts = "".join(f'<label><input type="checkbox" data-part="{p}" checked> {t}</label>'
                    for p, t in _PARTS)  # fmt: skip
    return f"""
<div id="cassi-controls">
 <button id="cassi-back" title="one data line back (left arrow)">&#9664; line</button>
 <button id="cassi-play" title="play or pause (space)">play</button>
 <button id="cassi-fwd" title="one data line on (right arrow)">line &#9654;</button>
 <input id="cassi-scrub" type="range" min="0" max="0" step="1" value="0"
  aria-label="frame">
 <span id="cassi-clock"></span>
</div>
<div id="cassi-timeline"></div>
<div id="cassi-options">
 <label>speed <select id="cassi-speed"><option value="1">1</option>
  <option value="0.5">0.5</option><option value="0.25">0.25</option></select></label>
 <span>view {presets}</span>
 <label>skin <select id="cassi-skin"><option value="solid">solid</option>
  <option value="see-through">see-through</option><option value="cut">cut (inside)</option>
  <option value="hidden">hidden</option></select></label>
 {parts}
 <label><input type="checkbox" data-pellets="measured" checked> measured pellets, trails</label>
 <label><input type="checkbox" data-pellets="model" checked> model pellet sites</label>
</div>"""


def _header(meta: dict[str, Any], sound_note: str) -> str:
    e = html.escape
    what = (f"{e(meta['format'])} recording {e(meta['file'])}" if meta["file"]
            else f"{e(meta['format'])} recording")  # fmt: skip
    lines = ("every data line" if meta["stride"] == 1
             else f"one in {meta['stride']} data lines")  # fmt: skip
    mode = "" if meta["calibration"] == "cassi mode" else f" ({e(meta['mode'])} mode)"
    return (
        f"<header><h1>{e(meta['subject'])} {e(meta['task'])}</h1><p>"
        f"subject <b>{e(meta['subject'])}</b> &middot; task <b>{e(meta['task'])}</b> &middot; "
        f"{what} &middot; {meta['rate_hz']:.1f} Hz, {meta['frames']} frames "
        f"({lines}) "
        f"&middot; jaw method <b>{e(meta['jaw_method'])}</b> &middot; calibration "
        f"<b>{e(meta['calibration'])}</b>{mode} &middot; {e(sound_note)}"
        "</p></header>"
    )


def _error_words(error_mm: float) -> str:
    return "under 0.001 mm" if error_mm < 0.0005 else f"at most {error_mm:.3f} mm"


def page_html(data: dict[str, Any], *, sound: bytes | None = None,
              sound_note: str = "no sound") -> str:  # fmt: skip
    """The page's HTML of ``data`` (:func:`cassi_fit.viewer._data.page_data`) with the
    ``.wav`` bytes ``sound`` (or none)."""
    meta = data["meta"]
    blob = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    audio = ""
    if sound is not None:
        audio = ('<audio id="cassi-audio" preload="auto" src="data:audio/wav;base64,'
                 f'{base64.b64encode(sound).decode()}"></audio>')  # fmt: skip
    footer = (
        f"Every data line is a frame; the face's motion is stored PCA-compressed "
        f"({meta['components']} components over {meta['moving_vertices']} moving vertices, "
        f"{_error_words(meta['max_error_mm'])} from the toolkit's vertices). Written by "
        "cassi_fit (cassi view); drawn with three.js (MIT licence)."
    )
    title = html.escape(f"cassi_fit: {meta['subject']} {meta['task']}")
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{title}</title>'
        f'<link rel="icon" href="data:,"><style>{_STYLE}</style></head><body>\n'
        f"{_header(meta, sound_note)}\n"
        '<div id="cassi-main"><div id="cassi-view"><canvas id="cassi-3d"></canvas>'
        '<div id="cassi-nogl"></div></div><canvas id="cassi-section"></canvas></div>'
        f"{_controls()}\n"
        '<div id="cassi-plots"><canvas id="cassi-plot-jaw"></canvas>'
        '<canvas id="cassi-plot-lips"></canvas></div>\n'
        f"{audio}\n<footer>{html.escape(footer)}</footer>\n"
        f'<script id="cassi-data" type="application/json">{blob}</script>\n'
        f"<script>{_asset('viewer.js')}</script>\n</body></html>\n"
    )


@dataclass(frozen=True)
class ViewerPage:
    """One recording's viewer page: ``html`` (the whole self-contained file) and ``meta``
    (what the header says). Shown inline in Jupyter (an ``iframe`` holding the page);
    :meth:`save` writes the file."""

    html: str
    meta: dict[str, Any]

    @property
    def size_bytes(self) -> int:
        return len(self.html.encode("utf-8"))

    def save(self, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
        """Write the page to ``path`` (atomically; an existing file only with ``overwrite``)."""
        from .._io import atomic_write

        return atomic_write(Path(path), self.html, overwrite=overwrite)

    def _repr_html_(self) -> str:
        return (f'<iframe srcdoc="{html.escape(self.html, quote=True)}" '
                f'style="width:100%;height:{IFRAME_HEIGHT_PX}px;border:0" '
                'sandbox="allow-scripts"></iframe>')  # fmt: skip

    def __repr__(self) -> str:
        m = self.meta
        return (f"ViewerPage({m['subject']} {m['task']}, {m['frames']} frames, "
                f"{self.size_bytes / 1e6:.2f} MB)")  # fmt: skip


def _tiers(labels: Any) -> list[dict[str, Any]]:
    """Label tiers for the page from a ``labels.Labels`` or a sequence of them."""
    if labels is None:
        return []
    many = labels if isinstance(labels, (list, tuple)) else [labels]
    return [{"name": t.tier, "segments": [[float(s), float(e), str(x)] for s, e, x in
                                          zip(t.starts, t.ends, t.labels, strict=True)]}
            for t in many if t is not None and len(t)]  # fmt: skip


def _run_of(recording: Any, spec: Any, changes: dict[str, Any]) -> Any:
    """A ``pipeline.RecordingRun`` of a run, a ``dataset.Recording`` or a file's path."""
    from ..pipeline import RecordingRun, run_recording

    if isinstance(recording, RecordingRun):
        return recording
    if isinstance(recording, (str, os.PathLike)):
        from ..dataset import load_recording

        recording = load_recording(recording)
    changes = {"stride": 1, **changes}  # every data line is a frame of the page
    return run_recording(recording, spec, **changes)


def view(recording: Any, spec: Any = None, *, labels: Any = True, sound: bool = True,
         accept_mismatch: bool = False, **changes: Any) -> ViewerPage:  # fmt: skip
    """The viewer page of a recording: ``recording`` is a ``pipeline.RecordingRun``, a
    ``dataset.Recording`` or a recording file's path (run with ``spec``, a
    ``run_spec.RunSpec`` or a preset's name, and ``changes``; every data line a frame
    unless ``stride=`` says otherwise). ``labels``: True for the recording's labels (a
    file beside it, or the tiers inside the file where this version reads them; checked
    against its length), a ``labels.Labels`` or a list of them, or None/False. ``sound``:
    embed the recording's sound (the ``.wav`` beside it, or the sound inside the file where
    this version reads it; checked against its length); ``accept_mismatch`` keeps sound or labels
    whose length does not fit (with a warning). In Jupyter the page shows inline; save it
    with ``.save(path)``."""

    run = _run_of(recording, spec, changes)
    rec = run.recording
    length_s = rec.track.length_s
    if labels is True:
        labels = _recording_labels(rec, length_s, accept_mismatch)
    wav, note = _sound(rec, length_s, accept_mismatch) if sound else (None, "sound left out")
    data = page_data(run, labels=_tiers(labels or None))
    return ViewerPage(page_html(data, sound=wav, sound_note=note), data["meta"])


def _recording_labels(rec: Any, length_s: float, accept_mismatch: bool) -> Any:
    """The labels every output uses: ``labels.recording_labels`` where this version has it
    (a file beside, else the tiers inside the recording file), else the file beside."""
    from .. import labels as labels_module

    inside_too = getattr(labels_module, "recording_labels", None)
    if inside_too is not None:
        return inside_too(rec, recording_s=length_s, accept_mismatch=accept_mismatch)
    if rec.path is None:
        return None
    return labels_module.labels_for(rec.path, recording_s=length_s,
                                    accept_mismatch=accept_mismatch)  # fmt: skip


def _sound(rec: Any, length_s: float, accept_mismatch: bool) -> tuple[bytes | None, str]:
    """``(.wav bytes or None, the header's words)``: the recording's sound (``Recording.sound``
    where this version has it: the ``.wav`` beside, else the sound inside the file; else
    the ``.wav`` beside), checked against its length."""
    from ..sound import check_sound

    held = getattr(rec, "sound", None)
    if held is not None and hasattr(held, "check"):
        checked = held.check(length_s, accept_mismatch=accept_mismatch)
        data = held.data if held.data is not None else Path(held.path).read_bytes()
        name = Path(held.path).name if held.path is not None else held.source
        return data, f"sound {name} ({checked.sound_s:.2f} s, {checked.rate_hz} Hz)"
    if rec.audio is None:
        return None, "no sound with this recording"
    checked = check_sound(rec.audio, length_s, accept_mismatch=accept_mismatch)
    return (Path(rec.audio).read_bytes(),
            f"sound {Path(rec.audio).name} ({checked.sound_s:.2f} s, {checked.rate_hz} Hz)")


def write_view(path: str | os.PathLike, recording: Any, spec: Any = None, *,
               overwrite: bool = False, **options: Any) -> Path:  # fmt: skip
    """Write :func:`view`'s page of ``recording`` (``options`` as :func:`view`) to
    ``path``. Returns the path written."""
    return view(recording, spec, **options).save(path, overwrite=overwrite)
