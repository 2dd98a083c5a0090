"""The corpus forms of the commands (issue 15): `cassi jaw DATASET`, `cassi evaluate` and
`cassi calibrate` give byte-identical tables in this process, with --jobs 2 and on a
dask.distributed LocalCluster; a broken file is one failed row and a non-zero exit; --resume
after an interrupted run does only the rest; `cassi animate DATASET` writes one video per
recording."""

import shutil
from pathlib import Path

import pytest

from cassi_fit import cli
from cassi_fit.corpus import MARKER_DIR
from cassi_fit.labels import Labels, write_lab, write_textgrid
from cassi_fit.synth import generate_corpus

TASKS = ("tp040", "tp106")  # the synthetic corpus's two shortest speech tasks
# evaluate and calibrate: one short task per subject, evaluate at every 20th line (the
# parallel machinery is what is tested; the measures have their own tests): 34 frames,
# in the frame bucket of the animate test below (and of most animations in the suite),
# so the animation's compiled kernels are shared, not compiled again for 64-128 frames
SMALL = ["--tasks", "tp040"]


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """2 subjects x 2 tasks; S01 tp040 labelled by a .lab, S02 tp106 by a TextGrid."""
    root = generate_corpus(tmp_path_factory.mktemp("corpus"), n_subjects=2, tasks=TASKS,
                           audio=False)
    write_lab(root / "S01" / "TP040.lab", Labels([0.5, 1.0], [1.0, 1.5], ("pa", "ta")))
    write_textgrid(root / "S02" / "TP106.TextGrid",
                   Labels([0.2, 0.9], [0.6, 1.3], ("ba", "da"), tier="words"))
    return root


@pytest.fixture(scope="module")
def dask_cluster():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=None)
    yield cluster
    cluster.close()


def _cassi(*words) -> int:
    return cli.main([str(w) for w in words])


def _tables(out: Path) -> dict[str, bytes]:
    """Every table the run wrote (CSV, Parquet, Markdown, JSON; markers and images
    aside), by relative path."""
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*"))
            if p.is_file() and MARKER_DIR not in p.parts and p.suffix != ".png"}


COMMANDS = {
    "jaw": lambda corpus, out: ["jaw", corpus, "--out", out],
    "evaluate": lambda corpus, out: ["evaluate", corpus, "--out", out, "--stride", "20",
                                     *SMALL],
    "calibrate": lambda corpus, out: ["calibrate", corpus, "--out", out, *SMALL],
}


@pytest.fixture(scope="module")
def serial(corpus, tmp_path_factory):
    """Each command run in this process (--jobs 1): its output folder."""
    outs = {}
    for name, words in COMMANDS.items():
        out = tmp_path_factory.mktemp(f"serial-{name}")
        assert _cassi(*words(corpus, out), "--jobs", 1, "--quiet") == 0
        outs[name] = out
    return outs


def test_serial_tables(serial):
    jaw = serial["jaw"]
    assert {"jaw_corpus.csv", "S01/tp040.jaw.csv", "S01/tp040.segments.csv",
            "S02/tp106.segments.csv"} <= set(_tables(jaw))
    table = (jaw / "jaw_corpus.csv").read_text().splitlines()
    assert len(table) == 5 and all(",ok,," in line for line in table[1:])
    assert (jaw / "S02" / "tp106.jaw.csv").read_text().splitlines()[0].endswith(",label")
    evaluation = (serial["evaluate"] / "evaluation_recordings.csv").read_text().splitlines()
    assert len(evaluation) == 3 and all("tp040" in line for line in evaluation[1:])
    calibration = (serial["calibrate"] / "calibration_corpus.csv").read_text().splitlines()
    assert [line.split(",")[:3] for line in calibration[1:]] == [["S01", "", "ok"],
                                                                 ["S02", "", "ok"]]
    assert {"S01.calibration.json", "S02.calibration.json", "calibration_summary.csv"} <= set(
        _tables(serial["calibrate"]))


@pytest.mark.parametrize("name", list(COMMANDS))
def test_two_jobs_give_identical_tables(name, serial, corpus, tmp_path, capsys):
    assert _cassi(*COMMANDS[name](corpus, tmp_path), "--jobs", 2) == 0
    assert "(2 workers)" in capsys.readouterr().err  # one bar, with the worker count
    assert _tables(tmp_path) == _tables(serial[name])


# On Dask the heavy calibrate is left out: the runner hands every command's jobs to the
# executor the same way (--jobs 2 covers calibrate), and each Dask worker would compile the
# calibration anew (about 20 s of the suite).
@pytest.mark.parametrize("name", ["jaw", "evaluate"])
def test_dask_cluster_gives_identical_tables(name, serial, corpus, dask_cluster, tmp_path):
    assert _cassi(*COMMANDS[name](corpus, tmp_path), "--scheduler",
                  dask_cluster.scheduler_address, "--quiet") == 0
    assert _tables(tmp_path) == _tables(serial[name])


def test_broken_file_is_a_failed_row_and_a_nonzero_exit(corpus, tmp_path, capsys):
    broken = tmp_path / "corpus"
    shutil.copytree(corpus, broken)
    (broken / "S02" / "TP999.TXY").write_text("0\t1\t2\n")  # 3 fields, not 17
    assert _cassi("jaw", broken, "--out", tmp_path / "out", "--jobs", 1, "--quiet") == 1
    err = capsys.readouterr().err
    assert "1 of 5 failed:" in err and "S02 tp999:" in err and "TP999.TXY:1:" in err
    rows = (tmp_path / "out" / "jaw_corpus.csv").read_text().splitlines()
    assert [r.split(",")[2] for r in rows[1:]] == ["ok"] * 4 + ["failed"]
    assert rows[-1].startswith("S02,tp999,failed,") and "TP999.TXY:1:" in rows[-1]


def test_resume_after_an_interruption_does_only_the_rest(serial, corpus, tmp_path, capsys):
    out = tmp_path / "out"
    shutil.copytree(serial["jaw"], out)
    # as if the run had stopped after S01's recordings: S02's outputs and markers absent
    shutil.rmtree(out / "S02")
    shutil.rmtree(out / MARKER_DIR / "S02")
    (out / "jaw_corpus.csv").unlink()
    kept = (out / "S01" / "tp040.jaw.csv").stat().st_mtime_ns
    assert _cassi("jaw", corpus, "--out", out, "--jobs", 1, "--resume", "--quiet") == 0
    assert "resumed: 2 of 4 already done" in capsys.readouterr().err
    assert (out / "S01" / "tp040.jaw.csv").stat().st_mtime_ns == kept  # not redone
    assert _tables(out) == _tables(serial["jaw"])


def test_evaluate_resume_takes_the_rows_from_the_markers(serial, corpus, tmp_path, capsys):
    out = tmp_path / "out"
    shutil.copytree(serial["evaluate"], out)
    for name in ("evaluation_subjects.csv", "evaluation_recordings.csv", "evaluation.md"):
        (out / name).unlink()
    assert _cassi(*COMMANDS["evaluate"](corpus, out), "--resume", "--jobs", 1) == 0
    assert "resumed: 2 of 2 already done" in capsys.readouterr().err
    assert _tables(out) == _tables(serial["evaluate"])


def test_a_dataset_needs_out_and_an_earlier_run_needs_resume_or_force(serial, corpus,
                                                                     capsys):
    # --csv is one recording's: a folder of several is refused, naming how to choose one
    assert _cassi("jaw", corpus, "--csv", "x.csv") == 2
    assert "recordings: name one as DATASET SUBJECT TASK" in capsys.readouterr().err
    assert _cassi("jaw", corpus) == 2
    assert "give --out DIR for its tables" in capsys.readouterr().err
    assert _cassi("jaw", corpus, "--out", serial["jaw"], "--quiet") == 2
    assert "file exists" in capsys.readouterr().err


def test_animate_dataset_writes_one_video_per_recording(corpus, tmp_path, capsys):
    out = tmp_path / "videos"
    assert _cassi("animate", corpus, "--out", out, "--format", "gif", "--size", "96x72",
                  "--views", "front", "--stride", "40", "--jobs", 1, "--quiet") == 0
    rows = (out / "animate_corpus.csv").read_text().splitlines()
    assert len(rows) == 5 and all(",ok,," in r for r in rows[1:])
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*.gif")) == [
        "S01/tp040.gif", "S01/tp106.gif", "S02/tp040.gif", "S02/tp106.gif"]
    assert "TP040.lab" in rows[1] and "TP106.TextGrid" in rows[4]
