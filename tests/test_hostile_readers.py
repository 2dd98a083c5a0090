"""Files and maps that lie, on the readers' side (issue 28 part 6): each is one error naming
the file, or its values are untracked; never data at the origin, never a hang, never a
recording refused for a companion file. Each case was checked to fail on the code before
these fixes."""

import shutil
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest
from ema_files import MOCHA_CHANNELS, mocha_header, mocha_values
from special_files import FifoGuard, make_fifo

from cassi_fit import cli
from cassi_fit.dataset import CompanionFileWarning, DefaultHeadMeasuresWarning, load_recording
from cassi_fit.ema.carstens import read_pos
from cassi_fit.ema.est import read_est, write_est
from cassi_fit.ema.sensor_map import read_sensor_map, sensor_map
from cassi_fit.ema.synthetic import load_ema_truth, write_ema_corpus
from cassi_fit.errors import CassiError, DataFormatError
from cassi_fit.labels import LabelMismatchWarning, labels_for
from cassi_fit.pellets import PELLET_NAMES
from cassi_fit.sound import SoundMismatchWarning, check_sound
from cassi_fit.synth import generate_corpus

MNI = PELLET_NAMES.index("MNI")


def _quiet(load, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DefaultHeadMeasuresWarning)
        return load(*args, **kw)


def _one_line_naming(err, path):
    text = str(err.value)
    assert str(path) in text and "\n" not in text, text


@pytest.fixture(scope="module")
def corpora(tmp_path_factory):
    root = tmp_path_factory.mktemp("hostile")
    xrmb = generate_corpus(root / "xrmb", n_subjects=1, tasks="tp040")
    return {"xrmb": xrmb, **{fmt: write_ema_corpus(root / fmt, format=fmt, from_corpus=xrmb)
                              for fmt in ("est", "ag501")}}


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


# ------------------------------------------------------------ zeros and absurd values
def _mocha_file(path: Path, n: int, zero: tuple[str, ...]) -> Path:
    body = b""
    for i in range(n):
        values = mocha_values(i)
        for name in zero:  # a dead coil: both of its channels exported as exact zeros
            for axis in ("x", "y"):
                values[MOCHA_CHANNELS.index(f"{name}_{axis}")] = 0.0
        body += struct.pack("<22f", 0.002 * i, 1.0, *values)
    path.write_bytes(mocha_header(n) + body)
    return path


@pytest.mark.parametrize("dead,role", [("li", "MNI"), ("tt", "T1")])
def test_an_est_channel_of_zeros_is_untracked(tmp_path, dead, role):
    path = _mocha_file(tmp_path / "fsew0_001.ema", 40, (dead,))
    rec = _quiet(load_recording, path)
    assert not rec.track.valid[:, PELLET_NAMES.index(role)].any()  # never at the origin
    assert any("dead channel" in n for n in rec.sensors.notes)
    assert rec.track.valid[:, PELLET_NAMES.index("UL")].all()


def test_a_csv_column_of_zeros_is_untracked(tmp_path, corpora):
    truth = load_ema_truth(corpora["est"], "S01", "tp040")
    names = ("UL", "LL", "TT", "TB", "TD", "LI")
    ok = np.all([np.isfinite(truth.positions[s]).all(-1) for s in names], axis=0)
    header = "time," + ",".join(f"{s}_{a}" for s in names for a in "xy")
    rows = [",".join([f"{t:.4f}"] + [f"{v:.4f}" for s in names for v in truth.positions[s][i]])
            for i, t in enumerate(truth.times) if ok[i]]
    path = tmp_path / "s01_tp040.csv"
    path.write_text("\n".join([header] + rows) + "\n")
    assert _quiet(load_recording, path).track.valid[:, PELLET_NAMES.index("T1")].all()
    cells = [r.split(",") for r in rows]
    for c in cells:
        c[1 + 2 * names.index("TT")] = "0"  # the TT_x column: all zeros
    path.write_text("\n".join([header] + [",".join(c) for c in cells]) + "\n")
    rec = _quiet(load_recording, path)
    assert not rec.track.valid[:, PELLET_NAMES.index("T1")].any()
    assert rec.track.valid[:, PELLET_NAMES.index("T2")].all()


def _rewrite_est(src: Path, change) -> None:
    raw = read_est(src)
    positions = raw.positions.copy()
    change(positions, raw.names)
    new = src.with_name("new.ema")
    write_est(new, type(raw)(format=raw.format, times=raw.times, names=raw.names,
                             positions=positions, rate_hz=raw.rate_hz, units="mm", axes="x"))
    new.replace(src)  # the reader registered src as an input: never overwritten in place


def test_a_jaw_dropout_to_zero_with_z_kept_is_untracked(tmp_path, corpora):
    folder = _copy(corpora["est"] / "S01", tmp_path / "S01")
    _rewrite_est(folder / "tp040.ema",
                 lambda p, names: p.__setitem__((slice(100, 150), names.index("LI"),
                                                 slice(0, 2)), 0.0))
    rec = _quiet(load_recording, folder / "tp040.ema")
    valid = rec.track.valid[:, MNI].all(-1)
    assert not valid[100:150].any() and valid[:100].any() and valid[150:].any()


def test_one_absurd_value_is_untracked(tmp_path, corpora):
    folder = _copy(corpora["est"] / "S01", tmp_path / "S01")
    _rewrite_est(folder / "tp040.ema",
                 lambda p, names: p.__setitem__((200, names.index("LI"), 0), 1e6))
    rec = _quiet(load_recording, folder / "tp040.ema")
    valid = rec.track.valid[:, MNI].all(-1)
    assert not valid[200] and valid[199] and valid[201]
    assert np.nanmax(np.abs(rec.track.positions)) < 300


# ------------------------------------------------------------------ an AG501 header
def test_an_ag501_header_claiming_half_the_channels_is_refused(tmp_path, corpora):
    src = corpora["ag501"] / "S01" / "tp040.pos"
    raw = read_pos(src)
    from cassi_fit.ema.carstens import write_pos

    k = len(raw.names)
    extra = raw.positions[:, : 16 - k] + 30.0  # 16 channels in all
    full = type(raw)(format="ag501", times=raw.times,
                     names=raw.names + tuple(f"X{i}" for i in range(16 - k)),
                     positions=np.concatenate([raw.positions, extra], axis=1),
                     rate_hz=raw.rate_hz, units="mm", axes="x")
    path = write_pos(tmp_path / "tp040.pos", full)
    assert read_pos(path).n_frames == raw.n_frames
    data = path.read_bytes().replace(b"NumberOfChannels=16", b"NumberOfChannels=08")
    path.write_bytes(data)
    with pytest.raises(DataFormatError, match="fit 16 channels") as err:
        read_pos(path)
    _one_line_naming(err, path)


# ---------------------------------------------------------------------- sensor maps
def test_a_sensor_map_scale_of_infinity_is_an_error(tmp_path):
    path = tmp_path / "sensors.toml"
    path.write_text("[file]\nscale_mm = inf\n")
    with pytest.raises(DataFormatError, match="finite") as err:
        read_sensor_map(path)
    _one_line_naming(err, path)


def test_a_sensor_map_that_is_a_fifo_is_an_error_and_never_opened(tmp_path):
    fifo = make_fifo(tmp_path / "sensors.toml")
    with FifoGuard(fifo) as guard:
        with pytest.raises(CassiError) as err:
            sensor_map(fifo)
    assert guard.opened == []
    _one_line_naming(err, fifo)


# -------------------------------------------------------------- companion files
def test_a_mocha_palate_trace_beside_never_refuses_the_recording(tmp_path):
    root = tmp_path / "fsew0_v1.1"
    root.mkdir()
    _mocha_file(root / "fsew0_001.ema", 20, ())
    (root / "fsew0_pal.dat").write_text("3.5829 11.2044\n-5.1 14.88\n-20.4 15.9\n")
    with pytest.warns(CompanionFileWarning, match="fsew0_pal.dat"):
        rec = _quiet(load_recording, root / "fsew0_001.ema")
    assert rec.palate is None and rec.track.valid[:, 0].all()


# ----------------------------------------------------------- XRMB labels and sound
@pytest.mark.parametrize("rows", [
    ["1200.0 1850.5 she", "1850.5 2400.25 had"],  # milliseconds, a part of the recording
    ["30000 36000.0 she", "36000.0 41000.0 had"],  # samples at 16 kHz, a part
])
def test_labels_all_past_the_end_are_an_error_unless_accepted(tmp_path, corpora, rows,
                                                              capsys):
    folder = _copy(corpora["xrmb"] / "S01", tmp_path / "S01")
    txy = folder / "TP040.TXY"
    lab = txy.with_suffix(".lab")
    lab.write_text("\n".join(rows) + "\n")
    with pytest.raises(DataFormatError, match="after the recording ends|likely times") as err:
        labels_for(txy)
    _one_line_naming(err, lab)
    with pytest.warns(LabelMismatchWarning):
        assert len(labels_for(txy, accept_mismatch=True)) == 2
    out = tmp_path / "jaw.csv"  # --quiet: still one line naming the label file, exit 2
    assert cli.main(["jaw", str(txy), "--csv", str(out), "--quiet"]) == 2
    err_text = capsys.readouterr().err
    assert str(lab) in err_text and err_text.count("\n") == 1 and not out.exists()


def test_a_wav_cut_to_half_its_bytes_is_an_error_naming_it(tmp_path, corpora):
    folder = _copy(corpora["xrmb"] / "S01", tmp_path / "S01")
    wav = folder / "TP040.WAV"
    import wave

    with wave.open(str(wav)) as w:
        seconds = w.getnframes() / w.getframerate()
    wav.write_bytes(wav.read_bytes()[: wav.stat().st_size // 2])
    with pytest.raises(DataFormatError, match="the file is cut") as err:
        check_sound(wav, seconds)
    _one_line_naming(err, wav)
    with pytest.warns(SoundMismatchWarning):
        assert check_sound(wav, seconds, accept_mismatch=True).sound_s < 0.6 * seconds


def test_the_untracked_jaw_pellets_error_names_the_file(tmp_path, corpora, capsys):
    folder = _copy(corpora["xrmb"] / "S01", tmp_path / "S01")
    txy = folder / "TP040.TXY"
    lines = txy.read_text().splitlines()
    cells = [line.split() for line in lines]
    for c in cells:  # MNI and MNM (the last four columns) untracked on every line
        c[13:17] = ["1000000"] * 4
    txy.write_text("\n".join("\t".join(c) for c in cells) + "\n")
    assert cli.main(["jaw", str(txy), "--csv", str(tmp_path / "jaw.csv")]) == 2
    err_text = capsys.readouterr().err
    assert str(txy) in err_text and "never tracked" in err_text
