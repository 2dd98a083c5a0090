"""The corpus runner: identical tables in this process, on a local process pool and on a
Dask cluster; a broken file becomes one FAILED row; an interrupted run resumes with only
the rest; markers check their outputs; the jaw task's per-recording and corpus tables."""

import shutil
import threading
from pathlib import Path

import numpy as np
import pytest

from cassi_fit.corpus import (
    WORKER_DIED,
    CorpusItem,
    TaskResult,
    csv_text,
    dataset_items,
    item_rng,
    load_item,
    marker_path,
    run_corpus,
    worker_model,
)
from cassi_fit.errors import OutputExistsError
from cassi_fit.jaw_table import jaw_corpus, jaw_corpus_path, jaw_output_path, segments_output_path
from cassi_fit.labels import Labels, write_lab
from cassi_fit.status import Status
from cassi_fit.synth import generate_corpus
from cassi_fit.tables import parquet_available

TASKS = ("tp040", "tp106")  # the synthetic corpus's two shortest speech tasks


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """2 subjects x 2 tasks, one of them labelled, plus one broken pellet file (S02/TP999)."""
    root = generate_corpus(tmp_path_factory.mktemp("corpus"), n_subjects=2, tasks=TASKS,
                           audio=False)
    write_lab(root / "S01" / "TP040.lab", Labels([0.5, 1.0], [1.0, 1.5], ("pa", "ta")))
    (root / "S02" / "TP999.TXY").write_text("0\t1\t2\n")  # 3 fields, not 17
    return root


@pytest.fixture(scope="module")
def serial(corpus, tmp_path_factory):
    """The reference run: in this process (jobs=1)."""
    out = tmp_path_factory.mktemp("serial")
    run, written, _ = jaw_corpus(corpus, out, run_options={"jobs": 1, "progress": False})
    parquet = [jaw_corpus_path(out).with_suffix(".parquet")] if parquet_available() else []
    assert written == [jaw_corpus_path(out), *parquet]
    return out, run


def _outputs(out: Path) -> dict[str, bytes]:
    """Every table the run wrote (markers aside), by relative path."""
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*"))
            if p.is_file() and ".cassi-corpus" not in p.parts}


def test_broken_file_is_one_failed_row_and_the_rest_run(serial, corpus):
    out, run = serial
    assert [(r.item.subject, r.item.task) for r in run.results] == [
        ("S01", "tp040"), ("S01", "tp106"), ("S02", "tp040"), ("S02", "tp106"),
        ("S02", "tp999")]
    assert [r.status for r in run.failed] == [Status.FAILED]
    bad = run.failed[0]
    assert bad.item.task == "tp999" and "TP999.TXY:1:" in bad.error and "\n" not in bad.error
    assert not marker_path(out, bad.item).exists()
    assert "1 of 5 failed" in run.failure_summary() and "tp999" in run.failure_summary()
    rows = run.rows()
    assert [r["status"] for r in rows] == ["ok"] * 4 + ["failed"]
    ok = rows[0]
    assert ok["method"] == "closed-form" and ok["frames"] > 100
    assert ok["frames_ok"] + ok["frames_invalid_frame"] + ok["frames_pivot_undefined"] == (
        ok["frames"])
    assert 2.0 < ok["theta_range_deg"] < 30.0 and 0.0 < ok["residual_rms_mm"] < 2.0
    assert ok["label_file"] == "TP040.lab" and rows[1]["label_file"] == ""


def test_jaw_csv_per_recording_with_labels(serial, corpus):
    out, run = serial
    item = run.results[0].item
    lines = jaw_output_path(out, item).read_text().splitlines()
    header = lines[0].split(",")
    assert header[-1] == "label" and header[:2] == ["time_s", "theta_deg"]
    rows = [line.split(",") for line in lines[1:]]
    assert len(rows) == run.results[0].row["frames"]
    by_label = {r[-1] for r in rows if 0.5 <= float(r[0]) < 1.0}
    assert by_label == {"pa"}
    assert {r[-1] for r in rows if float(r[0]) >= 1.5} == {""}
    no_labels = jaw_output_path(out, run.results[1].item).read_text().splitlines()[0]
    assert not no_labels.endswith(",label")
    # per-segment summaries from the same fit: the peak is the largest angle in the segment
    segments = segments_output_path(out, item).read_text().splitlines()
    assert segments[0].startswith("label,start_s,end_s,frames,status,jaw_peak_opening_deg")
    pa = dict(zip(segments[0].split(","), segments[1].split(","), strict=True))
    assert pa["label"] == "pa" and pa["status"] == "ok" and len(segments) == 3
    in_pa = [float(r[1]) for r in rows if 0.5 <= float(r[0]) < 1.0 and r[7] == "ok"]
    assert float(pa["jaw_peak_opening_deg"]) == pytest.approx(max(in_pa), abs=1e-6)
    assert not segments_output_path(out, run.results[1].item).exists()


def test_padding_to_a_frame_bucket_leaves_the_fit_unchanged(corpus):
    from cassi_fit.jaw_fit import jaw_bucket, jaw_from_track
    from cassi_fit.txy import read_txy

    track = read_txy(dataset_items(corpus)[0].path)
    assert jaw_bucket(track.n_frames) > track.n_frames  # so there is padding
    for method in ("closed-form", "frame-fit"):
        plain = jaw_from_track(track, method=method, pad_to=track.n_frames)  # no padding
        padded = jaw_from_track(track, method=method, pad_to=jaw_bucket(track.n_frames))
        default = jaw_from_track(track, method=method)  # padded to the bucket by default
        for name in ("theta", "translation", "pivot", "pivot_defined", "residual", "status",
                     "covariance", "pivot_covariance"):
            np.testing.assert_array_equal(getattr(padded, name), getattr(plain, name))
            np.testing.assert_array_equal(getattr(default, name), getattr(plain, name))
        assert (padded.noise_mm, padded.converged) == (plain.noise_mm, plain.converged)
    # the pivot fit sums its residuals over the padded frames too (zeros): the same fit to
    # rounding
    plain = jaw_from_track(track, method="fixed-pivot", pad_to=track.n_frames)
    default = jaw_from_track(track, method="fixed-pivot")
    np.testing.assert_allclose(default.theta, plain.theta, atol=1e-9)
    np.testing.assert_allclose(default.pivot, plain.pivot, atol=1e-6)
    np.testing.assert_array_equal(default.status, plain.status)


def test_jaw_corpus_refuses_to_replace_a_table_before_running(serial, corpus):
    out, _ = serial
    with pytest.raises(OutputExistsError, match="jaw_corpus.csv"):
        jaw_corpus(corpus, out, run_options={"jobs": 1, "progress": False})


def test_tables_are_written_as_csv_and_parquet(serial):
    pq = pytest.importorskip("pyarrow.parquet")

    out, run = serial
    csv = jaw_corpus_path(out)
    assert csv.read_text() == csv_text(run.rows())
    table = pq.read_table(csv.with_suffix(".parquet")).to_pylist()
    assert [r["task"] for r in table] == [r["task"] for r in run.rows()]
    assert table[0]["theta_range_deg"] == run.rows()[0]["theta_range_deg"]
    assert table[-1]["status"] == "failed" and table[-1]["theta_range_deg"] is None


def test_process_pool_gives_identical_tables(serial, corpus, tmp_path):
    out, reference = serial
    cache = tmp_path / "jax-cache"
    run = jaw_corpus(corpus, tmp_path / "out", run_options={
        "jobs": 2, "progress": False, "compilation_cache": cache}).run
    assert run.workers == 2
    assert any(cache.iterdir())  # the workers stored what they compiled
    assert _outputs(tmp_path / "out") == _outputs(out)


@pytest.fixture(scope="module")
def dask_cluster():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=None)
    yield cluster
    cluster.close()


def test_dask_cluster_gives_identical_tables(serial, corpus, dask_cluster, tmp_path):
    out, reference = serial
    from distributed import Client

    run = jaw_corpus(corpus, tmp_path / "address", run_options={
        "progress": False, "scheduler": dask_cluster.scheduler_address}).run
    assert run.workers == 2
    assert _outputs(tmp_path / "address") == _outputs(out)
    with Client(dask_cluster) as client:  # a Client passed as the executor
        again = jaw_corpus(corpus, tmp_path / "client",
                           run_options={"progress": False, "executor": client}).run
    assert again.workers == 2
    assert _outputs(tmp_path / "client") == _outputs(out)


# --------------------------------------------------------- resuming (in-process tasks)
CALLS: list[tuple[str, str]] = []
FINISHED: list[tuple[str, str]] = []
STOP_AT: list[tuple[str, str]] = []  # the item at which the "user" presses Ctrl-C
FAIL_AT: list[tuple[str, str]] = []  # items that fail besides S02 tp106


def counting_task(item: CorpusItem, out_dir: str, *, scale: float = 1.0,
                  reverse: bool = False, overwrite: bool = False) -> TaskResult:
    """Writes one small file per item; raises KeyboardInterrupt at ``STOP_AT`` (an
    interruption), ValueError for subject S02 task tp106 and ``FAIL_AT`` (failures).
    ``reverse``: on a pool running every item at once, each item waits for the one after
    it in (subject, task) order to finish, so they finish in reverse order."""
    key = (item.subject, item.task)
    if reverse:
        later = ORDER[ORDER.index(key) + 1:]
        if later:
            DONE[later[0]].wait()  # the pool runs every item at once: no deadlock
    try:
        return _count(item, out_dir, scale, overwrite)
    finally:
        if reverse:
            DONE[key].set()


def _count(item, out_dir, scale, overwrite):
    from cassi_fit._io import atomic_write

    CALLS.append((item.subject, item.task))
    if (item.subject, item.task) in STOP_AT:
        raise KeyboardInterrupt
    if (item.subject, item.task) in [("S02", "tp106"), *FAIL_AT]:
        raise ValueError("no jaw here\nsecond line")
    value = float(item_rng(item).normal()) * scale
    out = atomic_write(Path(out_dir) / f"{item.subject}_{item.task}.txt", f"{value!r}\n",
                       overwrite=overwrite)
    FINISHED.append((item.subject, item.task))
    return TaskResult({"value": value}, (str(out),))


ITEMS = [CorpusItem(s, t, "") for s in ("S02", "S01", "S10") for t in ("tp106", "tp040")]
ORDER = sorted((i.subject, i.task) for i in ITEMS)  # the table's order
DONE: dict = {}


def test_interrupted_run_resumes_with_only_the_rest(tmp_path):
    whole = run_corpus(counting_task, ITEMS, tmp_path / "whole", jobs=1, progress=False)
    CALLS.clear()
    STOP_AT[:] = [("S02", "tp040")]
    try:
        with pytest.raises(KeyboardInterrupt):
            run_corpus(counting_task, ITEMS, tmp_path / "part", jobs=1, progress=False)
    finally:
        STOP_AT.clear()
    done = [("S01", "tp040"), ("S01", "tp106")]  # natural (subject, task) order
    assert CALLS == [*done, ("S02", "tp040")]
    with pytest.raises(OutputExistsError, match="resume"):
        run_corpus(counting_task, ITEMS, tmp_path / "part", jobs=1, progress=False)
    CALLS.clear()
    rest = run_corpus(counting_task, ITEMS, tmp_path / "part", jobs=1, progress=False,
                      resume=True)
    assert sorted(CALLS) == sorted({(i.subject, i.task) for i in ITEMS} - set(done))
    assert rest.resumed == 2
    assert csv_text(rest.rows()) == csv_text(whole.rows())


def test_resume_skips_done_items_and_redoes_missing_outputs(tmp_path):
    CALLS.clear()
    first = run_corpus(counting_task, ITEMS, tmp_path, jobs=1, progress=False)
    assert len(CALLS) == 6 and [r.status for r in first.failed] == [Status.FAILED]
    assert first.failed[0].error == "ValueError: no jaw here second line"
    CALLS.clear()
    (tmp_path / "S10_tp040.txt").unlink()  # an output lost after its marker was written
    (tmp_path / "S01_tp106.txt").write_text("0.0\n")  # an output changed
    again = run_corpus(counting_task, ITEMS, tmp_path, jobs=1, progress=False, resume=True)
    assert sorted(CALLS) == [("S01", "tp106"), ("S02", "tp106"), ("S10", "tp040")]
    assert again.resumed == 3
    assert csv_text(again.rows()) == csv_text(first.rows())
    FAIL_AT[:] = [("S10", "tp040")]  # done before, fails now: its old marker must go
    try:
        failing = run_corpus(counting_task, ITEMS, tmp_path, jobs=1, progress=False,
                             overwrite=True)
    finally:
        FAIL_AT.clear()
    assert len(failing.failed) == 2 and not marker_path(tmp_path, ITEMS[5]).exists()
    CALLS.clear()
    run_corpus(counting_task, ITEMS, tmp_path, jobs=1, progress=False, resume=True)
    assert sorted(CALLS) == [("S02", "tp106"), ("S10", "tp040")]
    CALLS.clear()
    run_corpus(counting_task, ITEMS, tmp_path, jobs=1, progress=False, resume=True,
               options={"scale": 2.0})  # other settings: nothing counts as done
    assert len(CALLS) == 6


def test_any_executor_and_completion_order_give_the_same_table(tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    serial = run_corpus(counting_task, ITEMS, tmp_path / "serial", jobs=1, progress=False)
    FINISHED.clear()
    DONE.update({key: threading.Event() for key in ORDER})
    with ThreadPoolExecutor(max_workers=len(ITEMS)) as pool:
        threaded = run_corpus(counting_task, ITEMS, tmp_path / "threads", executor=pool,
                              progress=False, options={"reverse": True})
    assert threaded.workers == len(ITEMS)
    assert FINISHED == [k for k in reversed(ORDER) if k != ("S02", "tp106")]
    assert csv_text(threaded.rows()) == csv_text(serial.rows())


def crashing_task(item: CorpusItem, out_dir: str, *, overwrite: bool = False) -> TaskResult:
    """Kills its worker process for S01 tp106 (as a segfault or the OOM killer would)."""
    import os

    if (item.subject, item.task) == ("S01", "tp106"):
        os._exit(3)
    return TaskResult({"pid": 0})


def test_a_recording_that_kills_its_worker_is_one_failed_row(tmp_path):
    run = run_corpus(crashing_task, ITEMS, tmp_path, jobs=2, progress=False)
    assert [(r.item.subject, r.item.task) for r in run.failed] == [("S01", "tp106")]
    assert run.failed[0].error == WORKER_DIED
    assert len(run.results) == 6 and all(marker_path(tmp_path, r.item).exists()
                                         for r in run.results if r.status == Status.OK)


def jax_settings_task(item: CorpusItem, out_dir, *, overwrite: bool = False) -> TaskResult:
    """What JAX computes with in the worker that runs it."""
    import jax

    return TaskResult({"x64": bool(jax.config.jax_enable_x64),
                       "rank_promotion": str(jax.config.jax_numpy_rank_promotion)})


def test_workers_trace_as_the_starting_process_does():
    # conftest sets float64 and rank promotion 'raise' here; a worker that allowed rank
    # promotion would hide what this process refuses, and its kernels' keys would differ
    # from this process's (so it traced again what this process exported)
    import jax

    assert jax.config.jax_numpy_rank_promotion == "raise" and jax.config.jax_enable_x64
    run = run_corpus(jax_settings_task, ITEMS[:2], None, jobs=2, progress=False)
    assert [r.row for r in run.results] == [{"x64": True, "rank_promotion": "raise"}] * 2


def test_the_settings_the_workers_take_are_read_one_way(monkeypatch):
    """``_current(name)``: this process's JAX setting (float64, the rank promotion rule)
    as JAX has it, and None for each before JAX starts (JAX not imported to read it)."""
    import sys

    import jax

    from cassi_fit.corpus import _executor

    assert _executor._current("jax_enable_x64") is jax.config.jax_enable_x64 is True  # conftest's
    assert _executor._current("jax_numpy_rank_promotion") == "raise"
    monkeypatch.delitem(sys.modules, "jax")
    assert _executor._current("jax_enable_x64") is None
    assert _executor._current("jax_numpy_rank_promotion") is None
    assert "jax" not in sys.modules  # not started by asking (monkeypatch puts it back)


def test_one_progress_bar_with_the_worker_count(tmp_path, capsys):
    run_corpus(counting_task, ITEMS, tmp_path, jobs=1, progress=True, desc="jaw")
    err = capsys.readouterr().err
    assert "jaw (1 worker)" in err and "1 failed" in err
    assert err.count("\n") <= 1  # one bar, redrawn in place, not one per item


def test_worker_model_is_loaded_once_per_content(tmp_path):
    from cassi_fit.face_model import default_model_dir

    model = worker_model()
    assert worker_model() is model
    copy = shutil.copytree(default_model_dir(), tmp_path / "model")
    assert worker_model(copy) is model  # same files, same digest: no second load


def test_dataset_items_choices_and_per_subject(corpus):
    items = dataset_items(corpus, subjects=["s02"], tasks=["TP106", "tp040"])
    assert [(i.subject, i.task) for i in items] == [("S02", "tp040"), ("S02", "tp106")]
    assert all(Path(i.path).is_absolute() and Path(i.path).is_file() for i in items)
    subjects = dataset_items(corpus, per_subject=True, tasks=["tp106"])
    assert [(i.subject, i.task, i.path) for i in subjects] == [
        ("S01", "", str(corpus)), ("S02", "", str(corpus))]
    assert marker_path("out", subjects[0]) == Path("out/.cassi-corpus/S01/_subject.json")


def test_load_item_finds_the_subject_data(corpus):
    recording = load_item(dataset_items(corpus)[0])
    assert (recording.subject, recording.task) == ("S01", "tp040")
    assert recording.palate is not None and not recording.head_is_default


def test_item_rng_depends_only_on_seed_subject_task():
    a, b = CorpusItem("S01", "tp040", "x"), CorpusItem("S01", "tp040", "y")
    assert item_rng(a).normal() == item_rng(b).normal()
    assert item_rng(a).normal() != item_rng(a, seed=1).normal()
    assert item_rng(a).normal() != item_rng(CorpusItem("S01", "tp106", "x")).normal()
    assert np.isfinite(item_rng(a).normal())


def test_a_wait_for_the_pool_answers_a_signal_another_thread_received():
    """Ctrl-C handed by the system to another thread of the process (the pool's manager,
    tqdm's monitor) reaches Python's handler only when the main thread runs: the corpus
    runner's wait wakes to let it (``_executor._wait``), where a wait without a timeout
    slept until the work was done (a run left waiting for ever). The interrupt comes while
    the task still runs."""
    import concurrent.futures as cf
    import signal
    import threading

    from cassi_fit.corpus import _executor

    release = threading.Event()

    def task():  # the signal to this worker thread, not to the main one, once it waits
        release.wait(0.5)
        signal.pthread_kill(threading.get_ident(), signal.SIGINT)
        release.wait(60)

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with cf.ThreadPoolExecutor(1) as pool:
            try:
                with pytest.raises(KeyboardInterrupt):
                    future = pool.submit(task)
                    _executor._wait([future])
                assert not future.done()  # answered while the work went on
            finally:
                release.set()
    finally:
        signal.signal(signal.SIGINT, previous)
