"""``cassi jaw``: reads a pellet file, writes one CSV row per frame, refuses to overwrite."""

import csv

import jax
import numpy as np
import pytest

from cassi_fit import cli, rigid
from cassi_fit.txy import PelletTrack, write_txy

REFERENCE = np.array([[-2.0, -18.0], [-35.0, -24.0]])
PIVOT = np.array([-88.0, -8.0])


@pytest.fixture(scope="module")
def pellet_file(tmp_path_factory):
    n = 60
    theta = np.linspace(0.0, 0.2, n)
    jaw = np.asarray(jax.vmap(lambda th: rigid.apply(*rigid.from_pivot(th, PIVOT), REFERENCE))(
        theta))
    positions = np.zeros((n, 8, 2))
    # lips and tongue in a plausible posture (read_txy checks the anatomy)
    positions[:, :6] = [[15.0, 18.0], [9.0, -21.0], [-17.0, 1.0], [-28.0, 8.0], [-39.0, 15.0],
                        [-53.0, 17.0]]
    positions[:, 6:] = jaw
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
        "status"]
    assert [r["status"] for r in rows[:2]] == ["invalid-frame"] * 2
    assert rows[30]["status"] == "invalid-frame" and rows[40]["status"] == "ok"
    # the reference is frame 2; the motion is relative to it (pellets stored in whole um)
    expected = np.rad2deg(theta[40] - theta[2])
    assert float(rows[40]["theta_deg"]) == pytest.approx(expected, abs=0.01)
    assert float(rows[40]["pivot_a_mm"]) == pytest.approx(PIVOT[0], abs=0.5)
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
