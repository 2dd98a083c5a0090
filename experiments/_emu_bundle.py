"""A minimal private reader of one EMU-webApp bundle (``*_bndl.json``) for the acoustic
referee: its sound, its ``Segment`` labels, its formant track (``fms``) and its sensors as a
:class:`~cassi_fit.dataset.Recording`. The toolkit's own EMU reader is ``cassi_fit.ema``'s
(issue 28); this one reads only what the experiment needs, SSFF as the bundle's README
describes it (little-endian, header lines up to ``-----------------``)."""

from __future__ import annotations

import base64
import io
import json
import wave
from pathlib import Path

import numpy as np

SENSORS = {"t_tip": "ttip", "t_mid": "tm", "t_back": "tback", "upper_lip": "ul",
           "lower_lip": "ll", "jaw": "jaw"}
PADDING_RECORDS = 40  # the bundle's last 0.2 s of every track are zeros (README)
_TYPES = {"SHORT": "<i2", "FLOAT": "<f4", "DOUBLE": "<f8", "LONG": "<i4", "BYTE": "u1"}


def read_ssff(data: bytes) -> tuple[dict, dict[str, np.ndarray]]:
    """``(header, columns)`` of SSFF bytes: header keys ``Record_Freq``, ``Start_Time``;
    each column ``(n, width)``."""
    end = data.index(b"-----------------\n")
    header, columns = {}, []
    for line in data[:end].decode("latin-1").splitlines()[1:]:
        parts = line.split()
        if parts and parts[0] == "Column":
            columns.append((parts[1], _TYPES[parts[2]], int(parts[3])))
        elif len(parts) >= 2 and parts[0] in ("Record_Freq", "Start_Time"):
            header[parts[0]] = float(parts[1])
    dtype = np.dtype([(name, t, (w,)) for name, t, w in columns])
    rec = np.frombuffer(data[end + 18:], dtype=dtype)
    return header, {name: np.asarray(rec[name], np.float64) for name, _, _ in columns}


def load_bundle(path: str | Path) -> dict:
    """``{"samples", "rate", "segments": [(start s, end s, label)], "fms": (times, fm, bw),
    "ema": (times, {sensor: (n, 3)})}`` of one bundle."""
    bundle = json.loads(Path(path).read_text())
    with wave.open(io.BytesIO(base64.b64decode(bundle["mediaFile"]["data"]))) as w:
        rate = float(w.getframerate())
        raw = np.frombuffer(w.readframes(w.getnframes()), "<i2").astype(np.float64) / 32768.0
    ann = bundle["annotation"]
    sr = float(ann["sampleRate"])
    level = next(lv for lv in ann["levels"] if lv["name"] == "Segment")
    segments = [(it["sampleStart"] / sr, (it["sampleStart"] + it["sampleDur"]) / sr,
                 it["labels"][0]["value"]) for it in level["items"]]
    tracks = {}
    for f in bundle["ssffFiles"]:
        tracks[f["fileExtension"]] = read_ssff(base64.b64decode(f["data"]))
    head, cols = tracks["fms"]
    n = len(cols["fm"])
    fms_t = head.get("Start_Time", 0.0) + np.arange(n) / head["Record_Freq"]
    ema = {}
    for ext in SENSORS:
        h, c = tracks[ext]
        xyz = np.column_stack([c[k][:, 0] for k in c][:3])
        ema[ext] = xyz[:-PADDING_RECORDS]
        rate_ema = h["Record_Freq"]
    m = len(next(iter(ema.values())))
    return {"samples": raw, "rate": rate, "segments": segments,
            "fms": (fms_t, cols["fm"], cols["bw"]),
            "ema": (np.arange(m) / rate_ema, ema, rate_ema)}


def bundle_recording(path: str | Path):
    """The bundle's sensors as a :class:`~cassi_fit.dataset.Recording` (midsagittal x =
    -posy, front positive; y = posz, up), no palate or pharynx traces, default head
    measures, no sound file (the sound is in the bundle)."""
    from cassi_fit.dataset import Recording
    from cassi_fit.ema.arrays import raw_from_array
    from cassi_fit.ema.track import ema_to_track
    from cassi_fit.headmeasures import DEFAULT_HEAD_MEASURES

    b = load_bundle(path)
    _, ema, rate = b["ema"]
    cols, values = [], []
    for ext, name in SENSORS.items():
        cols += [f"{name}_x", f"{name}_y"]
        values += [-ema[ext][:, 1], ema[ext][:, 2]]
    raw = raw_from_array(np.column_stack(values), layout=cols, rate=rate, units="mm")
    track, report = ema_to_track(raw)
    rec = Recording(subject="mo1", task="prosody_0024", track=track, palate=None, pharynx=None,
                    head=DEFAULT_HEAD_MEASURES, head_is_default=True, audio=None, path=None,
                    sensors=report)
    return rec, b
