"""The subject-fitting experiment: its helpers on hand-made numbers, the small run, the
dataset run and the notebook. Bounds on the runs are the numbers the experiment itself
documented in docs/generated/calibration_recovery.md (written by ``make experiments``).

The notebook, the small run and the dataset run share one notebook kernel (``runs``):
most of each one's time is JAX tracing and compiling the calibration and the animation
(with collisions projected, above all), which the notebook's plan (``subject_rows.TINY``)
shares with the other two; in one process that is done once instead of in every one."""

import csv
import sys
from pathlib import Path
from types import SimpleNamespace

import nbformat
import numpy as np
import pytest
from experiment_kernel import main_cell, setup_cell
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
import subject_fitting as sf  # noqa: E402
import subject_report  # noqa: E402
import subject_rows  # noqa: E402

RECOVERY = ROOT / "docs" / "generated" / "calibration_recovery.md"
NOTEBOOK = ROOT / "notebooks" / "subject_fitting.ipynb"
#: the subjects of the small plan (the notebook's and the small run's)
SMALL_SUBJECTS = tuple(f"S{i:02d}" for i in range(1, subject_rows.SMALL.n_subjects + 1))
#: the dataset run's ``--tasks``: one of its corpus's two (the small plan's), so the run
#: calibrates from one recording and evaluates one (the small run covers two), and shows
#: that ``--tasks`` leaves the other out
DATASET_TASK = subject_rows.SMALL.tasks[1]


def _doc_tables(path):
    """Every Markdown table of the file ``path`` (see ``_tables``)."""
    return _tables(Path(path).read_text(encoding="utf-8"))


def _tables(text):
    """Every Markdown table of ``text``: a list of tables, each a list of {header: cell}."""
    tables, block = [], []
    for line in [*text.splitlines(), ""]:
        if line.startswith("|"):
            block.append([c.strip() for c in line.strip().strip("|").split("|")])
        elif block:
            tables.append([dict(zip(block[0], row, strict=True)) for row in block[2:]])
            block = []
    return tables


def _bound(cell):
    """The largest value a printed upper bound ``cell`` stands for (it is the measured
    number rounded to the printed digits)."""
    return float(cell) + (0.5 * 10.0 ** -len(cell.split(".")[1]) if "." in cell else 0.5)


def _documented():
    summary, per_subject = _doc_tables(RECOVERY)
    return {r["method"]: r for r in summary}, {r["subject"]: r for r in per_subject}


def _calibration(upper, lower, width, scale, residuals, converged=True):
    return SimpleNamespace(upper_lip_thickness=upper, lower_lip_thickness=lower,
                           face_width=width, scale=scale, residuals=residuals,
                           converged=converged, head_is_default=False)


TRUTHS = {"S01": {"upper_lip_thickness": 10.0, "lower_lip_thickness": 20.0,
                  "face_width": 100.0, "scale": 1.0},
          "S02": {"upper_lip_thickness": 12.0, "lower_lip_thickness": 15.0,
                  "face_width": 140.0, "scale": 0.8}}


def _rows():
    cals = {"separate": {"S01": _calibration(10.3, 19.0, 100.0, 1.01, {"upper_lip": 0.1}),
                         "S02": _calibration(12.0, 15.6, 133.0, 0.8, {"gonion": 2.0})},
            "joint": {"S01": _calibration(9.9, 20.0, 101.0, 1.0, {"upper_lip": 0.2},
                                          converged=False)}}
    return subject_rows.recovery_rows(cals, TRUTHS)


def _csv(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_percent_error_is_signed_and_relative():
    assert subject_rows.percent_error(10.5, 10.0) == pytest.approx(5.0)
    assert subject_rows.percent_error(9.0, 12.0) == pytest.approx(-25.0)


def test_recovery_rows_compare_each_calibration_with_its_subject():
    rows = _rows()
    assert [(r["method"], r["subject"]) for r in rows] == [
        ("separate", "S01"), ("separate", "S02"), ("joint", "S01")]
    s1, s2, j1 = rows
    assert s1["upper_lip_thickness_error_percent"] == pytest.approx(3.0)
    assert s1["lower_lip_thickness_error_percent"] == pytest.approx(-5.0)
    assert s2["face_width_error_percent"] == pytest.approx(-5.0)
    assert s2["lower_lip_thickness_error_percent"] == pytest.approx(4.0)
    assert s1["true_scale"] == 1.0 and s1["scale_error_percent"] == pytest.approx(1.0)
    assert j1["converged"] is False and s1["converged"] is True
    # residual columns: the union of the groups, NaN where a calibration has none
    assert s1["residual_upper_lip_mm"] == 0.1 and np.isnan(s1["residual_gonion_mm"])
    assert s2["residual_gonion_mm"] == 2.0 and np.isnan(s2["residual_upper_lip_mm"])
    # without truth: the estimates and residuals only
    plain = subject_rows.recovery_rows({"joint": {"S01": _calibration(1, 2, 3, 4, {})}})
    assert plain == [{"method": "joint", "subject": "S01", "converged": True,
                      "head_is_default": False, "upper_lip_thickness_mm": 1.0,
                      "lower_lip_thickness_mm": 2.0, "face_width_mm": 3.0, "scale": 4.0}]


def test_recovery_rows_carry_the_lower_lip_error_and_the_tip_offset_difference():
    truths = {k: {**v, "true_tip_ahead_of_mni_mm": 1.5, "model_tip_ahead_of_mni_mm": 0.5,
                  "tip_offset_difference_mm": 1.0} for k, v in TRUTHS.items()}
    cals = {m: {"S01": _calibration(10.0, 21.2, 100.0, 1.0, {"gonion": 0.5, "gnathion": 2.0,
                                                             "lips_in_teeth": 0.0})}
            for m in subject_rows.METHODS}
    rows = subject_rows.recovery_rows(cals, truths)
    assert rows[0]["lower_lip_thickness_error_mm"] == pytest.approx(1.2)
    assert rows[0]["tip_offset_difference_mm"] == 1.0
    text = subject_report.recovery_markdown(rows)
    assert text.startswith(f"<!-- written by `{subject_report.DOCS_COMMAND}`")
    # the summary: what remains of the lower-lip error once the offset is accounted for
    summary, per_subject = _tables(text)
    assert summary[0]["lower minus offset, worst mm"] == "0.20"
    assert summary[0]["lower lip, worst abs error %"] == "6.00"
    assert summary[0]["gonion residual mm"] == "0.50-0.50"
    assert per_subject[0]["tip offset difference mm"] == "+1.00"
    assert per_subject[0]["lower error mm (separate)"] == "+1.20"
    # without the geometry columns (no truth of it) the table cannot be written
    with pytest.raises(KeyError):
        subject_report.recovery_markdown(_rows())


def test_worst_errors_and_the_tolerance():
    rows = _rows()
    worst = subject_rows.worst_errors(rows)
    assert worst[("separate", "lower_lip_thickness")] == pytest.approx(5.0)
    assert worst[("separate", "upper_lip_thickness")] == pytest.approx(3.0)
    assert worst[("joint", "face_width")] == pytest.approx(1.0)
    assert worst[("separate", "face_width")] == pytest.approx(5.0)
    # exactly 5 % is not within 5 %; the joint row alone is
    assert not subject_rows.all_within(rows)
    assert subject_rows.all_within(rows[2:])
    assert subject_rows.all_within(rows[2:], tolerance=1.0 + 1e-9)
    assert not subject_rows.all_within(rows[2:], tolerance=1.0 - 1e-9)
    rows[2]["face_width_error_percent"] = float("nan")
    assert not subject_rows.all_within(rows[2:])
    assert np.isnan(subject_rows.worst_errors(rows)[("joint", "face_width")])
    assert not subject_rows.all_within([])


def test_noise_summary_takes_median_and_max_per_level_and_method():
    rows = []
    for noise, errors in ((0.0, (0.0, 0.1, 0.2)), (2.0, (0.4, -1.0, 0.1))):
        for k, e in enumerate(errors):
            rows.append({"noise_scale": noise, "method": "separate", "subject": f"S{k}",
                         "upper_lip_thickness_mm": 10.0 + e, "true_upper_lip_thickness_mm": 10.0,
                         "upper_lip_thickness_error_percent": 10.0 * e})
    out = subject_rows.noise_summary(rows, quantities=("upper_lip_thickness",))
    assert [(r["noise_scale"], r["subjects"]) for r in out] == [(0.0, 3), (2.0, 3)]
    assert out[0]["median_abs_error_mm"] == pytest.approx(0.1)
    assert out[0]["max_abs_error_mm"] == pytest.approx(0.2)
    assert out[1]["median_abs_error_mm"] == pytest.approx(0.4)
    assert out[1]["max_abs_error_mm"] == pytest.approx(1.0)
    assert out[1]["max_abs_error_percent"] == pytest.approx(10.0)
    assert out[0]["noise_sd_mm"] == 0.0 and out[1]["noise_sd_mm"] == pytest.approx(0.3 * 2**0.5)


def test_depth_percentiles_take_the_deepest_key_per_frame():
    frames = np.arange(101.0)  # 0 .. 100 mm: the 95th percentile is 95
    zeros = np.zeros(101)
    depths = {"tongue_upper_teeth": frames, "tongue_lower_teeth": frames[::-1],
              "tongue_palate": zeros, "lips_upper_teeth": zeros, "lips_lower_teeth": frames / 10}
    out = subject_rows.depth_percentiles(depths)
    # per frame max(k, 100 - k): 50 once, 51 .. 100 twice each; the 96th of 101 sorted is 98
    assert out["tongue_in_teeth"] == pytest.approx(98.0)
    assert out["tongue_in_palate"] == 0.0
    assert out["lips_in_teeth"] == pytest.approx(9.5)
    assert subject_rows.depth_percentiles(depths, q=50)["lips_in_teeth"] == pytest.approx(5.0)


def test_csv_text_writes_the_first_rows_columns():
    text = subject_rows.csv_text([{"a": 1.23456789, "b": "x"}, {"a": 2.0, "b": True}])
    assert text == "a,b\n1.23457,x\n2,True\n"


def test_main_refuses_existing_outputs_before_any_work(tmp_path, capsys):
    (tmp_path / "lip_noise.png").write_bytes(b"mine")
    assert sf.main(["--small", "--out", str(tmp_path)]) == 1
    assert "lip_noise.png exists" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["lip_noise.png"]
    assert (tmp_path / "lip_noise.png").read_bytes() == b"mine"
    # the dataset mode has its own outputs, and refuses in the same way
    (tmp_path / "penetration.csv").write_text("mine")
    assert sf.main(["--dataset", str(tmp_path), "--out", str(tmp_path)]) == 1
    with pytest.raises(SystemExit):
        sf.main(["--tasks", "tp106", "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        sf.main(["--dataset", str(tmp_path), "--docs", str(tmp_path)])
    # a documentation table that exists is not replaced either
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "evaluation_totals.md").write_text("mine")
    assert sf.main(["--small", "--out", str(tmp_path / "new"), "--docs", str(docs)]) == 1
    assert "evaluation_totals.md exists" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One kernel runs the notebook top to bottom, then ``main`` of the small run (``--small
    --docs``) and of the dataset run (``--dataset`` on a one-subject corpus of the small
    plan's tasks, at its stride, ``--tasks`` choosing one of them: ``DATASET_TASK``).
    Returns ``part -> (outputs or None, error or None, tmp)`` for ``"notebook"`` (the
    notebook's executed cells), ``"small"`` and ``"dataset"`` (the stdout of ``main``);
    each test raises its own part's error."""
    tmp = tmp_path_factory.mktemp("subject_fitting_runs")
    corpus = subject_rows.make_corpus(tmp / "corpus", subject_rows.Plan(
        1, subject_rows.SMALL.tasks, 1))
    argv = {"small": ["--small", "--out", str(tmp / "small" / "out"),
                      "--docs", str(tmp / "small" / "docs")],
            "dataset": ["--dataset", str(corpus), "--out", str(tmp / "dataset" / "out"),
                        "--tasks", DATASET_TASK, "--stride", str(subject_rows.SMALL.stride)]}
    nb = nbformat.read(NOTEBOOK, as_version=4)
    notebook = list(nb.cells)
    setup = setup_cell("subject_fitting")  # this process's settings, then the experiment
    mains = {k: main_cell("subject_fitting", a) for k, a in argv.items()}
    nb.cells = [setup, *notebook, *mains.values()]
    client = NotebookClient(nb, timeout=None, kernel_name="python3",
                            resources={"metadata": {"path": str(ROOT / "notebooks")}})
    out = {}
    with client.setup_kernel():
        client.execute_cell(setup, 0)
        try:
            for i, cell in enumerate(notebook, start=1):
                client.execute_cell(cell, i)
            out["notebook"] = (nb.cells[1:len(notebook) + 1], None, tmp)
        except Exception as exc:  # noqa: BLE001 -- raised by its test
            out["notebook"] = (None, exc, tmp)
        for i, (part, cell) in enumerate(mains.items(), start=len(notebook) + 1):
            try:
                client.execute_cell(cell, i)
                text = "".join(o.get("text", "") for o in nb.cells[i].outputs
                               if o.get("name") == "stdout")
                out[part] = (text, None, tmp / part)
            except Exception as exc:  # noqa: BLE001
                out[part] = (None, exc, tmp / part)
    return out


def _part(runs, name):
    """``(result, folder)`` of one part of ``runs``; its error raised if it failed."""
    result, error, folder = runs[name]
    if error is not None:
        raise error
    return result, folder


def _main_output(runs, name):
    """``main``'s stdout in ``runs`` (its exit status asserted 0) and its folder."""
    text, folder = _part(runs, name)
    assert text.rstrip().splitlines()[-1] == "exit status 0", text[-2000:]
    return text, folder


@pytest.mark.slow
def test_small_run_explains_the_lower_lip_and_writes_the_docs_tables(runs):
    summary, per_subject = _documented()
    printed, folder = _main_output(runs, "small")
    out, docs = folder / "out", folder / "docs"
    for name in subject_report.output_names(synthetic=True):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    for name in subject_report.DOC_TABLES:
        first = (docs / name).read_text(encoding="utf-8").splitlines()[0]
        assert first.startswith(f"<!-- written by `{subject_report.DOCS_COMMAND}`"), name
    rows = _csv(out / "calibration_recovery.csv")
    assert sorted((r["method"], r["subject"]) for r in rows) == [
        (m, s) for m in sorted(subject_rows.METHODS) for s in SMALL_SUBJECTS]
    for r in rows:
        worst = summary[r["method"]]
        assert r["converged"] == "True"
        # the subjects' geometry does not depend on the tasks: the documented offsets
        assert float(r["tip_offset_difference_mm"]) == pytest.approx(
            float(per_subject[r["subject"]]["tip offset difference mm"]), abs=0.006)
        # the lower lip is off by that offset, up to what the docs say remains
        rest = float(r["lower_lip_thickness_error_mm"]) - float(r["tip_offset_difference_mm"])
        assert abs(rest) <= _bound(worst["lower minus offset, worst mm"]), r["subject"]
        # face width is set from Headmeasures: the model reaches the setting
        assert abs(float(r["face_width_error_percent"])) <= _bound(
            worst["face width (set from Headmeasures), worst abs difference %"])
        # the estimates are not the truth copied: the lips carry the pellet noise
        assert float(r["upper_lip_thickness_mm"]) != float(r["true_upper_lip_thickness_mm"])
    noise = _csv(out / "lip_noise.csv")
    assert sorted({float(r["noise_scale"]) for r in noise}) == list(subject_rows.NOISE_SCALES)
    # without noise the upper lip (seen directly) is exact, with noise it is not; the
    # lower lip without noise is off by the largest offset difference, not 0
    at = {(float(r["noise_scale"]), r["method"], r["quantity"]): r for r in noise}
    assert float(at[0.0, "separate", "upper_lip_thickness"]["max_abs_error_mm"]) < 1e-6
    assert float(at[2.0, "separate", "upper_lip_thickness"]["max_abs_error_mm"]) > 0.01
    offsets = [abs(float(per_subject[s]["tip offset difference mm"])) for s in SMALL_SUBJECTS]
    assert float(at[0.0, "separate", "lower_lip_thickness"]["max_abs_error_mm"]) == pytest.approx(
        max(offsets), abs=_bound(summary["separate"]["lower minus offset, worst mm"]))
    penetration = _csv(out / "penetration.csv")
    assert len(penetration) == len(SMALL_SUBJECTS) * len(subject_rows.SMALL.tasks)
    assert all(r["status"] == "ok" for r in penetration)
    # projection leaves (almost) nothing of the tongue in the teeth
    for r in penetration:
        assert float(r["calibrated_after_tongue_in_teeth_p95_mm"]) < 0.1
    text = (out / "evaluation_comparison.md").read_text(encoding="utf-8")
    assert "CASSI-like" in text and "calibrated (separate)" in text
    totals = _doc_tables(docs / "evaluation_totals.md")[0]
    assert [r["setting"].split(" (")[0] for r in totals] == [
        "CASSI's Table 2", "CASSI-like", "calibrated", "calibrated"]
    assert all(sum(map(int, r["teeth"].split("/"))) == len(SMALL_SUBJECTS) for r in totals[1:])
    assert "lower lip: largest |error - tip offset difference|" in printed
    assert "face width is set from Headmeasures (not fitted)" in printed
    assert "ratings CASSI-like" in printed and "ratings calibrated" in printed


@pytest.mark.slow
def test_dataset_run_has_residuals_but_no_truth(runs):
    summary, _ = _documented()
    printed, folder = _main_output(runs, "dataset")
    out = folder / "out"
    for name in subject_report.output_names(synthetic=False):
        assert (out / name).is_file(), name
    assert not (out / "calibration_recovery.csv").exists()
    rows = _csv(out / "calibration_residuals.csv")
    assert [r["method"] for r in rows] == list(subject_rows.METHODS)
    assert not any(k.startswith("true_") or k.endswith("_percent") for k in rows[0])
    # S01 is one of the documented subjects: its jaw-shape residuals lie in the documented
    # ranges (0.05 mm: the scale here comes from 1 first line instead of 3)
    for r in rows:
        for point in ("gonion", "gnathion"):
            lo, hi = (float(v) for v in summary[r["method"]][f"{point} residual mm"].split("-"))
            assert lo - 0.05 <= float(r[f"residual_{point}_mm"]) <= hi + 0.05, (r["method"], point)
    assert "converged 1/1" in printed
    # --tasks: the evaluation and the penetration of that task alone
    assert [(r["subject"], r["task"]) for r in _csv(out / "penetration.csv")] == [
        ("S01", DATASET_TASK)]


@pytest.mark.slow
def test_notebook_runs_and_shows_figures_and_the_table(runs):
    cells, _ = _part(runs, "notebook")
    outputs = [o for cell in cells if cell.cell_type == "code" for o in cell.outputs]
    assert sum("image/png" in o.get("data", {}) for o in outputs) == 2
    tables = "".join(o.get("data", {}).get("text/markdown", "") for o in outputs)
    assert "| CASSI-like (1 subject) |" in tables
    assert "| calibrated + collisions (1 subject) |" in tables
    text = "".join(o.get("text", "") for o in outputs)
    assert "lower lip: largest |error - tip offset difference|" in text
