"""Articulograph recordings in datasets (cassi_fit.dataset): MOCHA-TIMIT's flat folders with
labels and sound beside, mngu0's names, bite-plane files and sensor maps beside, formats
told apart by content, `cassi info` on an EST file; and the real XRMB recording JW11 task
5 written by hand in MOCHA's EST layout comes back as the same pellets."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from ema_files import mocha_binary
from real_data import XRMB_JW11, missing, real_data

from cassi_fit import cli
from cassi_fit.dataset import Dataset, DefaultHeadMeasuresWarning, load_recording
from cassi_fit.ema.detect import detect_format
from cassi_fit.errors import DataFormatError
from cassi_fit.labels import labels_for
from cassi_fit.pellets import PELLET_NAMES
from cassi_fit.txy import read_txy

FIXTURES = Path(__file__).parent / "fixtures" / "ema"
_HERE = Path(__file__).resolve()
JW11 = real_data(XRMB_JW11)


def _quiet(load, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DefaultHeadMeasuresWarning)
        return load(*args, **kw)


@pytest.fixture
def mocha(tmp_path):
    """A MOCHA-TIMIT speaker folder as distributed: flat names, .ema + .lab + .wav."""
    root = tmp_path / "fsew0_v1.1"
    root.mkdir()
    (root / "fsew0_001.ema").write_bytes(mocha_binary(8))
    (root / "fsew0_002.ema").write_bytes(mocha_binary(5, "10"))
    (root / "fsew0_001.lab").write_bytes((FIXTURES / "fsew0_001.lab").read_bytes())
    (root / "fsew0_001.wav").write_bytes(b"RIFF")
    (root / "README").write_text("not a recording")
    return root


def test_mocha_folder_discovered_with_labels_and_sound(mocha):
    ds = Dataset(mocha)
    assert ds.subjects() == ["FSEW0"] and ds.tasks("fsew0") == ["001", "002"]
    rec = _quiet(ds.load, "FSEW0", "001")
    assert rec.format == "est" and rec.audio.name == "fsew0_001.wav"
    assert rec.track.frame_step_s == pytest.approx(0.002)
    labels = labels_for(rec.path)  # MOCHA's `start end phone` in seconds
    assert labels.labels == ("sil", "dh", "ax") and labels.ends[-1] == pytest.approx(0.44)
    ul, ll = (rec.track.positions[:, PELLET_NAMES.index(r)] for r in ("UL", "LL"))
    assert (ul[:, 1] > ll[:, 1]).all()


def test_cassi_info_on_a_mocha_file(mocha, capsys):
    assert cli.main(["info", str(mocha / "fsew0_001.ema")]) == 0
    text = capsys.readouterr().out
    assert "FSEW0 001" in text and "articulograph: est, 2D, 500 Hz" in text
    assert "MOCHA-TIMIT's documented axes" in text and "T4    (none)" in text
    assert cli.main(["info", str(mocha / "fsew0_001.ema"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(report["median_mm"]["UL"], [10.5, 8.5], atol=1e-4)
    assert report["median_mm"]["T4"] is None and report["extras_median_mm"]["bn"] == [15.0, 61.0]
    assert report["sensors"]["references"] == ["ui", "bn"]
    assert cli.main(["info", str(mocha)]) == 0
    assert "FSEW0: 2 task(s)" in capsys.readouterr().out


def test_names_bite_planes_and_sensor_maps_beside(tmp_path):
    flat = tmp_path / "mngu0"
    flat.mkdir()
    (flat / "mngu0_s1_0001.ema").write_bytes(mocha_binary(4))
    folder = tmp_path / "lab" / "P03"
    folder.mkdir(parents=True)
    (folder / "tp020_2.ema").write_bytes(mocha_binary(4))
    (folder / "bite.ema").write_bytes(mocha_binary(4))
    (folder / "sensors.toml").write_text('[roles]\nUL = "ul"\n')
    ds = Dataset(tmp_path / "lab")
    assert ds.subjects() == ["P03"] and ds.tasks("P03") == ["tp020_2"]  # bite: not a task
    assert Dataset(flat).tasks("MNGU0") == ["s1_0001"]
    # the bite file beside is used (and must hold bite-plane sensors: here it does not)
    with pytest.raises(DataFormatError, match=r"bite\.ema: bite-plane recording has no front"):
        _quiet(ds.load, "P03", "tp020_2")
    (folder / "bite.ema").unlink()
    rec = _quiet(ds.load, "P03", "tp020_2")
    assert rec.sensors.sensor_map.endswith("sensors.toml") and rec.subject == "P03"
    (folder / "sensors.toml").write_text('[roles]\nUL = "upper"\n')
    with pytest.raises(DataFormatError, match="role UL: sensor 'upper' is not in the file"):
        _quiet(load_recording, folder / "tp020_2.ema")


def test_formats_told_apart_by_content(tmp_path):
    (tmp_path / "a.pos").write_bytes(b"AG50xDATA_V002\n00000070\n" + b"\0" * 46)
    (tmp_path / "b.pos").write_bytes(b"\0" * (12 * 28))
    (tmp_path / "c.ema").write_bytes(mocha_binary(2))
    (tmp_path / "d.txt").write_bytes(mocha_binary(2))
    (tmp_path / "e.txy").write_text("0\t" + "\t".join(["1000000"] * 16) + "\r\n")
    (tmp_path / "f.dat").write_text("hello\n")
    found = {p.name: detect_format(p) for p in sorted(tmp_path.iterdir()) if p.name != "f.dat"}
    assert found == {"a.pos": "ag501", "b.pos": "ag500", "c.ema": "est", "d.txt": "est",
                     "e.txy": "xrmb"}
    with pytest.raises(DataFormatError, match=r"f\.dat: not a recording this toolkit reads"):
        load_recording(tmp_path / "f.dat")


@pytest.mark.skipif(JW11 is None, reason=missing(XRMB_JW11))
def test_real_jw11_recording_through_mocha_layout(tmp_path):
    """JW11 task 5 (one real recording of one speaker), written by hand as MOCHA does (x
    toward the back, 1/100 mm, NaN untracked, fixed ui and bn references): the EMA path
    gives back XRMB's own pellets."""
    xrmb = read_txy(JW11 / "jw11_tp005.txy")
    roles = {"ul": "UL", "ll": "LL", "tt": "T1", "tb": "T2", "td": "T3", "li": "MNI"}
    fixed = {"ui": (0.0, 0.0), "bn": (15.0, 60.0)}
    channels = [f"{s}_{a}" for s in [*roles, *fixed] for a in "xy"]
    lines = ["EST_File Track", "DataType ascii", f"NumFrames {xrmb.n_frames}",
             f"NumChannels {len(channels)}", "BreaksPresent true"]
    lines += [f"Channel_{i} {c}" for i, c in enumerate(channels)] + ["EST_Header_End"]
    for k in range(xrmb.n_frames):
        values = []
        for sensor in [*roles, *fixed]:
            x, y = (xrmb.pellet(roles[sensor])[k] if sensor in roles else fixed[sensor])
            values += [-100 * x, 100 * y]
        lines.append(" ".join([f"{xrmb.times[k]:.6f}", "1"] + [f"{v:.3f}" for v in values]))
    path = tmp_path / "jw11_005.txt"
    path.write_text("\n".join(lines) + "\n")
    rec = _quiet(load_recording, path)
    for role in roles.values():
        j = PELLET_NAMES.index(role)
        want = xrmb.positions[:, j]
        ok = np.isfinite(want).all(-1)
        np.testing.assert_array_equal(rec.track.valid[:, j].all(-1), ok)
        np.testing.assert_allclose(rec.track.positions[ok, j], want[ok], atol=1e-4)
    assert rec.sensors.head_correction.startswith("rigid, 2 references")
