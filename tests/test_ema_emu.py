"""EMU-SDMS (issue 28 part 4): SSFF files written by hand from the format's description, the
real IPS Munich bundle (../shared/data/emu_ips_mo1, read-only) and a synthetic emuDB
written by ``write_ema_corpus(format="emu")`` whose truth the reader never sees."""

import base64
import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from real_data import EMU_MO1, missing, real_data

from cassi_fit.dataset import Dataset, DefaultHeadMeasuresWarning, load_recording
from cassi_fit.ema.detect import detect_format
from cassi_fit.ema.emu import read_emu
from cassi_fit.ema.ssff import parse_ssff, read_ssff
from cassi_fit.ema.synthetic import load_ema_truth, write_ema_corpus
from cassi_fit.errors import DataFormatError
from cassi_fit.labels import recording_labels
from cassi_fit.pellets import PELLET_NAMES

_HERE = Path(__file__).resolve()
IPS = real_data(EMU_MO1)
NO_IPS = missing(EMU_MO1)
IPS_BUNDLE = "dfgspp_mo1_prosody_0024_bndl.json"


def _quiet(load, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DefaultHeadMeasuresWarning)
        return load(*args, **kw)


def _pellet(track, role):
    return track.positions[:, PELLET_NAMES.index(role)]


# ------------------------------------------------------------------------- SSFF
def _hand_ssff(machine: str, order: str) -> bytes:
    header = (f"SSFF -- (c) SHLRC\nMachine {machine}\nRecord_Freq 100.0\nStart_Time 0.5\n"
              "Column a_posx DOUBLE 1\nColumn fm SHORT 2\nOriginal_Freq DOUBLE 16000.0\n"
              "-----------------\n").encode()
    body = b""
    for k in range(3):
        body += np.array([k + 0.25], f"{order}f8").tobytes()
        body += np.array([10 * k, -k], f"{order}i2").tobytes()
    return header + body


@pytest.mark.parametrize("machine,order", [("IBM-PC", "<"), ("SPARC", ">")])
def test_ssff_written_by_hand_is_read(machine, order):
    track = parse_ssff(_hand_ssff(machine, order), "hand.ssff")
    assert track.rate_hz == 100.0 and track.start_s == 0.5 and track.n_records == 3
    assert track.columns["a_posx"][:, 0].tolist() == [0.25, 1.25, 2.25]
    assert track.columns["fm"].tolist() == [[0, 0], [10, -1], [20, -2]]
    assert track.values == {"Original_Freq": 16000.0}
    assert track.times.tolist() == [0.5, 0.51, 0.52]


@pytest.mark.parametrize("mutate,words", [
    (lambda b: b.replace(b"SSFF -- (c) SHLRC", b"XSFF"), "not an SSFF file"),
    (lambda b: b.replace(b"Machine IBM-PC\n", b""), "no Machine"),
    (lambda b: b.replace(b"Machine IBM-PC", b"Machine PDP-11"), "unknown Machine"),
    (lambda b: b.replace(b"SHORT 2", b"SHORT x"), "count"),
    (lambda b: b.replace(b"SHORT 2", b"WORD 2"), "Column"),
    (lambda b: b.replace(b"Record_Freq 100.0", b"Record_Freq 0"), "not a rate"),
    (lambda b: b[:-3], "whole number"),
    (lambda b: b.replace(b"-----------------\n", b""), "never ends"),
])
def test_ssff_damaged_is_one_error_naming_the_file(tmp_path, mutate, words):
    path = tmp_path / "x.t_tip"
    path.write_bytes(mutate(_hand_ssff("IBM-PC", "<")))
    with pytest.raises(DataFormatError, match=words) as err:
        read_ssff(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


# ------------------------------------------------------------- the real IPS bundle
@pytest.fixture(scope="module")
def ips():
    if IPS is None:
        pytest.skip(NO_IPS)
    return IPS / IPS_BUNDLE


def test_real_ips_bundle_read(ips):
    raw = read_emu(ips)
    assert detect_format(ips) == "emu"
    assert sorted(raw.names) == ["jw", "ll", "tb", "tm", "tt", "ul"]
    assert raw.dims == 3 and raw.rate_hz == 200.0 and raw.n_frames == 800
    # the export's padding: the last 38 records of every track are exactly 0 (its README
    # says 40; the data say 38): untracked, never a sensor at the origin
    tracked = np.isfinite(raw.positions).all(-1)
    assert not tracked[762:].any() and tracked[:762].all()
    assert np.isfinite(raw.positions[:762, :, 0]).all()  # posx is used, not only y and z
    params = raw.sound.info()
    assert (params.framerate, params.nchannels, params.nframes) == (24000, 1, 96002)
    tiers = {t.tier: t for t in raw.labels}
    assert set(tiers) == {"Word", "Segment", "TT", "TB"} and len(tiers["Segment"]) == 38
    word = tiers["Word"]  # an ITEM level: timed by the segments it dominates
    assert word.labels == ("Klausur",)
    assert (word.starts[0], word.ends[0]) == pytest.approx((1.33, 1.71))


def test_real_ips_bundle_placed_by_its_builtin_map(ips):
    rec = _quiet(load_recording, ips)
    assert rec.sensors.sensor_map == "ips" and rec.sound is not None
    track = rec.track
    ul, ll, t1, t3 = (_pellet(track, r) for r in ("UL", "LL", "T1", "T3"))
    mid = slice(0, 700)
    assert (ul[mid, 0] > t1[mid, 0]).all() and (t1[mid, 0] > t3[mid, 0]).all()  # lips front
    assert (ul[mid, 1] > ll[mid, 1]).all()  # the upper lip above the lower
    assert not track.valid[762:].any()
    labels = recording_labels(rec)
    assert labels.tier == "Segment" and labels.labels[1] == "m"


def test_real_ips_folder_jaw_table_in_words(ips, tmp_path, capsys):
    """``cassi jaw FOLDER --csv``: the real database folder of one bundle stands for its
    recording; with its one jaw sensor, what cannot be estimated is said, never ``nan``."""
    from cassi_fit import cli

    assert cli.main(["jaw", str(ips.parent), "--csv", str(tmp_path / "j.csv")]) == 0
    captured = capsys.readouterr()
    assert "a dataset of one recording" in captured.err
    assert "no noise estimate" in captured.out and "distance -/- (one jaw sensor)" in captured.out
    assert "nan" not in captured.out.lower()


def test_real_ips_bundle_json_and_folder_agree(ips, tmp_path):
    """The same bundle as an emuDB on disk (written from the JSON's own bytes) reads the
    same as the JSON the webApp serves."""
    bundle = json.loads(ips.read_text())
    folder = tmp_path / "ema_db" / "0000_ses" / "dfgspp_bndl"
    folder.mkdir(parents=True)
    shutil.copyfile(IPS / "ema_DBconfig.json", tmp_path / "ema_db" / "ema_DBconfig.json")
    for entry in bundle["ssffFiles"]:
        (folder / f"dfgspp.{entry['fileExtension']}").write_bytes(
            base64.b64decode(entry["data"]))
    (folder / "dfgspp.wav").write_bytes(base64.b64decode(bundle["mediaFile"]["data"]))
    (folder / "dfgspp_annot.json").write_text(json.dumps(bundle["annotation"]))
    a, b = read_emu(ips), read_emu(folder)
    assert a.names == b.names
    np.testing.assert_array_equal(a.positions, b.positions)
    assert [t.labels for t in a.labels] == [t.labels for t in b.labels]
    ds = Dataset(tmp_path / "ema_db")
    assert ds.subjects() == ["0000"] and ds.tasks("0000") == ["dfgspp"]
    rec = _quiet(ds.load, "0000", "dfgspp")
    assert rec.sound.path == folder / "dfgspp.wav" and rec.sensors.sensor_map == "ips"


# ----------------------------------------------------------- a synthetic emuDB
@pytest.fixture(scope="module")
def emudb(tmp_path_factory):
    return write_ema_corpus(tmp_path_factory.mktemp("emu") / "db", format="emu",
                            n_subjects=1, tasks="tp040", seed=5)


def test_synthetic_emudb_is_messy_as_exports_are(emudb):
    config = json.loads(next(emudb.glob("*_DBconfig.json")).read_text())
    assert {d["columnName"].rsplit("_", 1)[1] for d in config["ssffTrackDefinitions"]} == {
        "posy", "posz"}
    bundle = emudb / "S01_ses" / "tp040_bndl"
    track = read_ssff(bundle / "tp040.trk_ul")
    assert (track.columns["UL_posx"][-40:] == 0).all() and (track.columns["UL_orix"][-40:] == 0).all()
    assert (bundle / "tp040.wav").is_file() and not (emudb / "S01_ses" / "tp040.wav").exists()


def test_synthetic_emudb_read_against_its_truth(emudb):
    ds = Dataset(emudb)
    assert ds.subjects() == ["S01"] and ds.tasks("S01") == ["tp040"]
    rec = _quiet(ds.load, "S01", "tp040")
    assert rec.format == "emu" and rec.palate is not None  # the session folder's PAL.DAT
    truth = load_ema_truth(emudb, "S01", "tp040")
    track = rec.track
    n = track.times.shape[0]
    assert not track.valid[n - 40:].any()  # the padding: untracked
    # rigid-invariant: the distance between the two lip sensors, per frame, as the truth
    ok = track.valid[:, [0, 1]].all((1, 2))
    got = np.linalg.norm(_pellet(track, "UL") - _pellet(track, "LL"), axis=-1)[ok]
    want = np.linalg.norm(truth.positions["UL"] - truth.positions["LL"], axis=-1)[ok]
    np.testing.assert_allclose(got, want, atol=0.05)
    assert rec.sound.kind == "EMU media" and rec.sound.info().framerate == 16000
    labels = recording_labels(rec)
    assert labels.tier == "Segment" and labels.labels[:2] == ("She", "had")
    assert {t.tier for t in rec.labels} == {"Word", "Segment"}


def test_bundle_json_as_the_webapp_serves_it(emudb, tmp_path):
    bundle = emudb / "S01_ses" / "tp040_bndl"
    files = [{"fileExtension": p.name.split(".", 1)[1], "encoding": "BASE64",
              "data": base64.b64encode(p.read_bytes()).decode()}
             for p in sorted(bundle.glob("tp040.trk_*"))]
    served = {"ssffFiles": files,
              "mediaFile": {"encoding": "BASE64",
                            "data": base64.b64encode((bundle / "tp040.wav").read_bytes()).decode()},
              "annotation": json.loads((bundle / "tp040_annot.json").read_text())}
    path = tmp_path / "tp040_bndl.json"
    path.write_text(json.dumps(served))
    a, b = read_emu(bundle), read_emu(path)
    np.testing.assert_array_equal(a.positions, b.positions)
    with b.sound.wav_file() as wav:
        assert wav.read_bytes() == (bundle / "tp040.wav").read_bytes()
    served["ssffFiles"][0]["data"] = "not base64!"
    path.write_text(json.dumps(served))
    with pytest.raises(DataFormatError, match="base64") as err:
        read_emu(path)
    assert str(path) in str(err.value)


def test_a_definition_naming_a_missing_column_is_an_error(emudb, tmp_path):
    db = tmp_path / "db"
    shutil.copytree(emudb, db)
    config_path = next(db.glob("*_DBconfig.json"))
    config = json.loads(config_path.read_text())
    config["ssffTrackDefinitions"][0]["columnName"] = "nothing_posy"
    config_path.write_text(json.dumps(config))
    with pytest.raises(DataFormatError, match="nothing_posy") as err:
        read_emu(db / "S01_ses" / "tp040_bndl")
    assert ".trk_" in str(err.value)


def test_commands_run_on_an_emudb(tmp_path, capsys):
    from cassi_fit import cli

    db = tmp_path / "db"
    assert cli.main(["synth", "--format", "emu", str(db), "--subjects", "1", "--tasks",
                     "tp040"]) == 0
    assert cli.main(["info", str(db)]) == 0
    out = capsys.readouterr().out
    assert "S01" in out and "tp040" in out and "bite" not in out.split("\n", 2)[2]
    assert cli.main(["info", str(db / "S01_ses" / "tp040_bndl")]) == 0
    out = capsys.readouterr().out
    assert "sound (EMU media" in out and "labels: in the file: Word (1), Segment (11)" in out
    csv = tmp_path / "jaw.csv"
    assert cli.main(["jaw", str(db), "S01", "tp040", "--csv", str(csv), "--quiet"]) == 0
    rows = csv.read_text().splitlines()
    column = rows[0].split(",").index("label")
    assert "She" in {r.split(",")[column] for r in rows[1:]}
    assert (tmp_path / "jaw.segments.csv").is_file()
