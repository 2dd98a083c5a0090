"""``cassi jaw``: reads a pellet file, writes one CSV row per frame, refuses to overwrite."""

import csv

import jax
import numpy as np
import pytest

from cassi_fit import cli, rigid
from cassi_fit.txy import PelletTrack, write_txy

REFERENCE = np.array([[-2.0, -18.0], [-35.0, -24.0]])
PIVOT = np.array([-88.0, -8.0])


def _opening_jaw(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(positions (n, 8, 2) mm, theta (n,) rad)``: the jaw turning 0-0.2 rad about PIVOT,
    lips and tongue held in a plausible posture (read_txy checks the anatomy)."""
    theta = np.linspace(0.0, 0.2, n)
    jaw = np.asarray(jax.vmap(lambda th: rigid.apply(*rigid.from_pivot(th, PIVOT), REFERENCE))(
        theta))
    positions = np.zeros((n, 8, 2))
    positions[:, :6] = [[15.0, 18.0], [9.0, -21.0], [-17.0, 1.0], [-28.0, 8.0], [-39.0, 15.0],
                        [-53.0, 17.0]]
    positions[:, 6:] = jaw
    return positions, theta


@pytest.fixture(scope="module")
def pellet_file(tmp_path_factory):
    n = 60
    positions, theta = _opening_jaw(n)
    valid = np.ones((n, 8, 2), bool)
    valid[:2] = False  # leading untracked rows, as in real files
    valid[30, 6] = False  # a dropout of MNI
    track = PelletTrack(times=np.arange(n) * 0.006866, positions=positions, valid=valid)
    path = tmp_path_factory.mktemp("data") / "jw99_tp001.txy"
    write_txy(path, track)
    return path, theta


def test_writes_one_row_per_frame(pellet_file, tmp_path, capsys):
    path, theta = pellet_file
    out = tmp_path / "jaw.csv"
    assert cli.main(["jaw", str(path), "--method", "fixed-pivot", "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.read_text().splitlines()))
    assert len(rows) == 60 and list(rows[0]) == [
        "time_s", "theta_deg", "pivot_a_mm", "pivot_b_mm", "tx_mm", "ty_mm", "residual_mm",
        "status", "mistrack"]
    assert [r["status"] for r in rows[:2]] == ["invalid-frame"] * 2
    assert rows[30]["status"] == "invalid-frame" and rows[40]["status"] == "ok"
    # the reference is frame 2; the motion is relative to it (pellets stored in whole um)
    expected = np.rad2deg(theta[40] - theta[2])
    assert float(rows[40]["theta_deg"]) == pytest.approx(expected, abs=0.01)
    # the file is noise-free up to its 1 um rounding: the one fitted pivot is the true one
    # to a few um (0.02 mm is 20x the rounding, far below the 5-30 mm a wrong model gives)
    for row in rows[2:]:
        if row["status"] != "ok":  # a frame whose data were not used: no pivot, no residual
            assert row["pivot_a_mm"] == row["pivot_b_mm"] == row["residual_mm"] == ""
            continue
        assert float(row["pivot_a_mm"]) == pytest.approx(PIVOT[0], abs=0.02)
        assert float(row["pivot_b_mm"]) == pytest.approx(PIVOT[1], abs=0.02)
    assert rows[0]["pivot_a_mm"] == rows[0]["residual_mm"] == ""  # before the first valid line
    assert "60 frames" in capsys.readouterr().out


def test_refuses_to_overwrite_and_reports_bad_input(pellet_file, tmp_path, capsys):
    path, _ = pellet_file
    out = tmp_path / "jaw.csv"
    out.write_text("keep me")
    assert cli.main(["jaw", str(path), "--csv", str(out)]) == 2
    assert "exists" in capsys.readouterr().err and out.read_text() == "keep me"
    assert cli.main(["jaw", str(path), "--csv", str(out), "--force"]) == 0
    assert out.read_text().startswith("time_s,")
    assert cli.main(["jaw", str(path), "--csv", str(path), "--force"]) == 2
    assert "input" in capsys.readouterr().err
    bad = tmp_path / "bad.txy"
    bad.write_text("0\t1\t2\n")
    assert cli.main(["jaw", str(bad), "--csv", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and err.count("\n") == 1
    assert cli.main(["jaw", "a", "b", "--csv", str(tmp_path / "y.csv")]) == 2


def test_writes_diagnostics_beside_the_csv(pellet_file, tmp_path, capsys):
    path, _ = pellet_file
    out = tmp_path / "fit.csv"
    assert cli.main(["jaw", str(path), "--method", "fixed-pivot", "--compare-methods",
                     "--csv", str(out)]) == 0
    rows = list(csv.DictReader((tmp_path / "fit.diagnostics.csv").read_text().splitlines()))
    assert [r["method"] for r in rows] == ["fixed-pivot", "closed-form", "frame-fit",
                                          "smooth-pivot"]
    fixed = rows[0]
    assert float(fixed["pivot_iqr_x_mm"]) == 0.0 and float(fixed["pivot_plausible_fraction"]) == 1
    assert float(fixed["jaw_distance_sd_mm"]) < 0.01  # noise-free file: rigid up to 1 um rounding
    assert fixed["hidden_error_median_mm"] == ""  # both sensors used: none hidden, blank
    printed = capsys.readouterr().out
    assert "plausible" in printed and "closed-form" in printed


def test_never_replaces_recording_data(pellet_file, tmp_path, capsys):
    path, _ = pellet_file
    folder = tmp_path / "JW99"
    folder.mkdir()
    txy = folder / "tp001.txy"
    txy.write_bytes(path.read_bytes())
    for name in ("PAL.DAT", "PHA.DAT", "Headmeasures.txt", "TP001.WAV", "tp002.txy"):
        target = folder / name
        target.write_text("precious")
        assert cli.main(["jaw", str(txy), "--csv", str(target), "--force"]) == 2
        err = capsys.readouterr().err
        assert "refusing" in err and err.count("\n") == 1
        assert target.read_text() == "precious"
    assert cli.main(["jaw", str(txy), "--csv", str(folder), "--force"]) == 2
    assert "folder" in capsys.readouterr().err
    assert cli.main(["jaw", str(txy), "--csv", str(folder / "PAL.DAT" / "x.csv")]) == 2
    assert "is a file" in capsys.readouterr().err


def test_a_fifo_is_refused_not_read(tmp_path, capsys):
    import os

    fifo = tmp_path / "pipe.txy"
    os.mkfifo(fifo)
    assert cli.main(["jaw", str(fifo), "--csv", str(tmp_path / "out.csv")]) == 2
    err = capsys.readouterr().err
    assert "not a regular file" in err and str(fifo) in err and err.count("\n") == 1


@pytest.mark.parametrize("value", ["-1", "nan", "inf", "0"])
def test_bad_smoothness_is_one_clear_error(pellet_file, tmp_path, capsys, value):
    path, _ = pellet_file
    out = tmp_path / "s.csv"
    assert cli.main(["jaw", str(path), "--method", "smooth-pivot", "--smoothness", value,
                     "--csv", str(out)]) == 2
    err = capsys.readouterr().err
    assert "smoothness must be a finite number > 0" in err and err.count("\n") == 1
    assert not out.exists()


def test_mistracked_rows_are_marked(tmp_path, capsys):
    n = 60
    positions, theta = _opening_jaw(n)
    positions[0, 6, 1] -= 30.0  # a mistrack in the first valid line
    positions[40, 6, 1] -= 30.0  # and one later
    track = PelletTrack(times=np.arange(n) * 0.006866, positions=positions,
                        valid=np.ones((n, 8, 2), bool))
    path = tmp_path / "jw98_tp001.txy"
    write_txy(path, track)
    out = tmp_path / "m.csv"
    assert cli.main(["jaw", str(path), "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.read_text().splitlines()))
    assert rows[0]["status"] == rows[40]["status"] == "mistracked"
    assert rows[40]["mistrack"].startswith("MNI:") and rows[30]["mistrack"] == ""  # and why
    assert float(rows[1]["theta_deg"]) == pytest.approx(0.0, abs=0.01)  # line 1 is the reference
    assert float(rows[30]["theta_deg"]) == pytest.approx(np.rad2deg(theta[30] - theta[1]),
                                                         abs=0.01)
    assert "2 mistracked" in capsys.readouterr().out


def test_labels_beside_the_file_add_a_column_and_segments(pellet_file, tmp_path, capsys):
    import shutil

    from cassi_fit.labels import Labels, write_lab

    path = tmp_path / pellet_file[0].name
    shutil.copy(pellet_file[0], path)
    write_lab(path.with_suffix(".lab"), Labels([0.05, 0.2], [0.2, 0.3], ("ma", "pa")))
    out = tmp_path / "jaw.csv"
    assert cli.main(["jaw", str(path), "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert {r["label"] for r in rows if 0.1 < float(r["time_s"]) < 0.15} == {"ma"}
    assert rows[-1]["label"] == ""  # after the last segment
    segments = list(csv.DictReader((tmp_path / "jaw.segments.csv").open()))
    assert [s["label"] for s in segments] == ["ma", "pa"]
    inside = [float(r["theta_deg"]) for r in rows
              if 0.2 <= float(r["time_s"]) < 0.3 and r["status"] == "ok"]
    assert float(segments[1]["jaw_peak_opening_deg"]) == pytest.approx(max(inside), abs=1e-6)
    assert "2 labelled segments (jw99_tp001.lab)" in capsys.readouterr().out


# --------------------------------------------------------------------- one jaw sensor
@pytest.mark.parametrize("sensor, hidden", [("MNI", "MNM"), ("MNM", "MNI")])
def test_one_sensor_adds_the_hidden_sensors_prediction(pellet_file, tmp_path, capsys, sensor,
                                                       hidden):
    path, _ = pellet_file
    out = tmp_path / "one.csv"
    assert cli.main(["jaw", str(path), "--jaw-sensors", sensor, "--method", "fixed-pivot",
                     "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.read_text().splitlines()))
    assert list(rows[0])[-2:] == [f"{hidden}_pred_x_mm", f"{hidden}_pred_y_mm"]
    # the prediction is the fitted motion applied to the hidden pellet's reference ...
    from cassi_fit.txy import read_txy

    positions, _ = _opening_jaw(60)
    k = ("MNI", "MNM").index(hidden) + 6
    ref = read_txy(path).positions[2, k]  # as stored: whole micrometres
    fitted = [i for i, r in enumerate(rows) if r["status"] != "invalid-frame"]
    assert all(r[f"{hidden}_pred_x_mm"] == r[f"{hidden}_pred_y_mm"] == ""
               for i, r in enumerate(rows) if i not in fitted)  # nothing predicted: blanks
    assert fitted[0] == 2 and (30 in fitted) == (sensor == "MNM")  # MNI's dropout: frame 30
    rows, positions = [rows[i] for i in fitted], positions[fitted]
    for r in rows:
        theta = np.deg2rad(float(r["theta_deg"]))
        moved = np.asarray(rigid.apply(theta, np.array([float(r["tx_mm"]), float(r["ty_mm"])]),
                                       ref))
        assert float(r[f"{hidden}_pred_x_mm"]) == pytest.approx(moved[0], abs=5e-6)
        assert float(r[f"{hidden}_pred_y_mm"]) == pytest.approx(moved[1], abs=5e-6)
    # ... and near the truth: a noise-free rotation about PIVOT by up to 11.5 degrees, whose
    # short arc places the pivot only roughly; the prior (mean 35 mm off) pulls it by 2-4 mm,
    # which moves the hidden pellet by up to 0.45 mm (a pivot 20 mm off: 1-2 mm)
    for r, p in zip(rows, positions[:, k], strict=True):
        assert float(r[f"{hidden}_pred_x_mm"]) == pytest.approx(p[0], abs=0.6)
        assert float(r[f"{hidden}_pred_y_mm"]) == pytest.approx(p[1], abs=0.6)
    diag = list(csv.DictReader((tmp_path / "one.diagnostics.csv").read_text().splitlines()))
    assert diag[0]["jaw_sensors"] == sensor
    assert diag[0]["prior"].startswith("pivot prior (-95, 25) mm")
    assert float(diag[0]["hidden_error_median_mm"]) < 0.3
    printed = capsys.readouterr().out
    assert f"{sensor} alone" in printed and "prior: pivot prior" in printed


def test_one_sensor_says_what_it_cannot_estimate(pellet_file, tmp_path, capsys):
    """With one jaw sensor (the default coupled rotation) there is no residual: the
    printout says so in words, never ``nan`` (the real one-sensor EMU recording has no
    second jaw sensor either, whose distance is then said as ``-/-``)."""
    path, _ = pellet_file
    assert cli.main(["jaw", str(path), "--jaw-sensors", "MNI",
                     "--csv", str(tmp_path / "one.csv")]) == 0
    printed = capsys.readouterr().out
    assert "no noise estimate (a fit with one jaw sensor leaves no residual)" in printed
    assert "nan" not in printed.lower()


@pytest.mark.parametrize("method", ["closed-form", "frame-fit"])
def test_two_sensor_methods_refuse_one_sensor_in_one_line(pellet_file, tmp_path, capsys,
                                                          method):
    path, _ = pellet_file
    out = tmp_path / "r.csv"
    assert cli.main(["jaw", str(path), "--jaw-sensors", "MNI", "--method", method,
                     "--csv", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{method} needs both jaw sensors (MNI and MNM)" in err and err.count("\n") == 1
    assert not out.exists()
    assert cli.main(["jaw", str(path), "--jaw-sensors", "T1", "--csv", str(out)]) == 2
    assert "jaw sensors must be one of MNI,MNM, MNI, MNM" in capsys.readouterr().err


def test_compare_methods_with_one_sensor_lists_the_methods_that_can_run(pellet_file, tmp_path):
    path, _ = pellet_file
    out = tmp_path / "c.csv"
    assert cli.main(["jaw", str(path), "--jaw-sensors", "MNM", "--method", "coupled-rotation",
                     "--compare-methods", "--csv", str(out)]) == 0
    rows = list(csv.DictReader((tmp_path / "c.diagnostics.csv").read_text().splitlines()))
    assert [r["method"] for r in rows] == ["coupled-rotation", "fixed-pivot", "smooth-pivot"]
    assert "learned from the real XRMB recording JW11" in rows[0]["prior"]


def test_dataset_form_takes_the_sensor_choice(pellet_file, tmp_path, capsys):
    import shutil

    path, _ = pellet_file
    data = tmp_path / "data"
    data.mkdir()
    shutil.copy(path, data / path.name)
    out = tmp_path / "out"
    assert cli.main(["jaw", str(data), "--out", str(out), "--jaw-sensors", "MNI",
                     "--method", "frame-fit"]) == 2
    assert "needs both jaw sensors" in capsys.readouterr().err and not out.exists()
    assert cli.main(["jaw", str(data), "--out", str(out), "--jaw-sensors", "MNI", "--method",
                     "coupled-rotation", "--jobs", "1", "--quiet"]) == 0
    (table,) = out.glob("*/*.jaw.csv")
    assert table.read_text().splitlines()[0].endswith("MNM_pred_x_mm,MNM_pred_y_mm")
    (row,) = csv.DictReader((out / "jaw_corpus.csv").read_text().splitlines())
    assert row["jaw_sensors"] == "MNI" and row["method"] == "coupled-rotation"
    assert row["prior"].startswith("coupling theta") and float(row["hidden_error_median_mm"]) >= 0
