"""Interruptions (issue 24, part 6): SIGINT and SIGTERM end a command with one line and
status 130, no traceback, no crash, no temporary file left, at moments the process itself
reports (through a pipe) that it has reached, never after a sleep guessed long enough."""

import gc
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from cassi_fit import _signals, synth

HERE = Path(__file__).resolve().parent
#: How long a run may take to answer before the test calls it hung (a guard against
#: waiting for ever, far beyond what the slowest machine needs; not a speed limit)
HANG_S = 300


@pytest.fixture(autouse=True)
def as_from_a_terminal():
    """Ctrl-C as a terminal's foreground command has it, whoever started the tests: a
    shell without job control starts a background job with SIGINT ignored (POSIX), every
    process it starts inherits that, and a command keeps a signal it was started to ignore
    (``_signals.interruptible``), so these tests would see no interrupt. This process's
    handlers for the tests here; the commands they start inherit no ignored signal (a
    handler is reset to the default when a program starts; no ``preexec_fn``, which forks
    a process JAX's threads run in)."""
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


class ExtensionFileLoader:
    """Named like importlib's loader of extension modules, so that a signal arriving in
    :meth:`create_module` finds the frames of an extension's initialisation."""

    def __init__(self):
        self.pending_when_done = None
        self.finished = False

    def create_module(self, spec):
        os.kill(os.getpid(), signal.SIGTERM)
        _python_call()  # the handler runs here, inside the "initialisation"
        self.pending_when_done = _signals._STATE.pending
        self.finished = True


def _python_call():
    return sum(k for k in range(100))


def _wait_for_the_interrupt(limit_s: float = 120.0) -> None:
    """Wait, running Python between short sleeps, until the re-delivered interrupt is
    raised; fail after ``limit_s`` instead of hanging. Not ``signal.pause()``: when the
    timer's signal lands between Python's last check for signals and the pause itself (a
    loaded machine descheduling the process for the timer's 20 ms), pause() waits for a
    signal that has already come and the test hangs for ever."""
    import time

    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        time.sleep(0.005)
    pytest.fail(f"the interrupt was not delivered again within {limit_s:.0f} s")


def test_an_interrupt_waits_until_an_extension_module_is_initialised():
    loader = ExtensionFileLoader()
    with _signals.interruptible():
        with pytest.raises(KeyboardInterrupt):
            loader.create_module(None)
            _wait_for_the_interrupt()  # the deferred interrupt comes back (its timer)
    assert loader.finished and loader.pending_when_done == signal.SIGTERM


def test_an_interrupt_a_gc_callback_swallowed_is_delivered_again(capfd):
    fired = []

    def callback(phase, info):
        if phase == "start" and not fired:
            fired.append(phase)
            os.kill(os.getpid(), signal.SIGINT)
            _python_call()  # raised here, inside the callback: Python drops it

    gc.callbacks.append(callback)
    try:
        with _signals.interruptible():
            with pytest.raises(KeyboardInterrupt):
                gc.collect()
                _wait_for_the_interrupt()  # delivered again
    finally:
        gc.callbacks.remove(callback)
    assert fired
    assert "Exception ignored" not in capfd.readouterr().err


def test_defer_interrupts_raises_at_the_end_of_the_block():
    done = []
    with _signals.interruptible():
        with pytest.raises(KeyboardInterrupt):
            with _signals.defer_interrupts():
                os.kill(os.getpid(), signal.SIGTERM)
                _python_call()
                done.append("block finished")
    assert done == ["block finished"]


# ------------------------------------------------------------ whole commands, real signals
# The child runs `cassi` (cli.main(), the program) with one function patched to report
# "reached" on stdout when the stage is reached, then wait for the test's signal.
_CHILD = """
import sys
sys.path.insert(0, {here!r})
import importlib, os
module, _, name = {target!r}.rpartition(".")
owner_name, _, attribute = name.rpartition(":")
mod = importlib.import_module(module)
owner = getattr(mod, owner_name) if owner_name else mod
original = getattr(owner, attribute)
calls = [0]
def reached(*args, **kwargs):
    calls[0] += 1
    if calls[0] == {after}:
        print("reached", flush=True)
        sys.stdin.readline()  # the signal comes while this waits
    return original(*args, **kwargs)
setattr(owner, attribute, reached)
from cassi_fit.cli import main
sys.exit(main())
"""


def _interrupt(tmp_path, target, argv, sig, *, after=1, group=False):
    """Run ``cassi ARGV`` with ``target`` ("module.Class:method") reporting its ``after``-th
    call; send ``sig`` (to the process group with ``group``, as a terminal's Ctrl-C does)
    once it has; (exit status, stderr)."""
    code = _CHILD.format(here=str(HERE), target=target, after=after)
    env = {**os.environ, "PYTHONFAULTHANDLER": "1"}
    proc = subprocess.Popen([sys.executable, "-c", code, *map(str, argv)], cwd=tmp_path,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env,
                            start_new_session=True)
    try:
        for line in proc.stdout:
            if line.strip() == "reached":
                break
        else:
            raise AssertionError(f"never reached {target}: {proc.wait()} {proc.stderr.read()}")
        (os.killpg if group else os.kill)(proc.pid, sig)
        try:  # a guard, not a speed limit: a run that ignores the signal never ends
            _, err = proc.communicate(timeout=HANG_S)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            raise AssertionError(f"the run was still going {HANG_S} s after the signal") from None
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, err


def _messages(stderr: str) -> list[str]:
    """stderr without the warning a recording without Headmeasures gives."""
    return [ln for ln in stderr.splitlines()
            if ln.strip() and "HeadMeasures" not in ln and "return load_recording" not in ln]


@pytest.fixture(scope="module")
def wagging(tmp_path_factory):
    """A short synthetic recording (the jaw wagging task)."""
    root = synth.generate_corpus(tmp_path_factory.mktemp("corpus"), n_subjects=1,
                                 tasks=[synth.JAW_WAGGING_TASK])
    return next(Path(root).rglob("*.[tT][xX][yY]"))


@pytest.mark.slow
@pytest.mark.parametrize(("name", "sig", "group"), [("x.gif", signal.SIGTERM, False),
                                                    ("x.mp4", signal.SIGINT, True)])
def test_animate_interrupted_while_rendering(wagging, tmp_path, name, sig, group):
    """SIGTERM three frames into a GIF (a segmentation fault before), Ctrl-C at the
    terminal (the whole group: ffmpeg too) three frames into an MP4."""
    argv = ["animate", wagging, "--stride", "12", "--size", "160x120", "--out",
            tmp_path / name, "--quiet"]
    # frames are drawn pipelined (Renderer.render_frames): _submit draws each one
    status, err = _interrupt(tmp_path, "cassi_fit.render._scene.Renderer:_submit", argv,
                             sig, after=4, group=group)
    assert status == 130, err
    assert _messages(err) == ["cassi: interrupted"]
    assert not [p.name for p in tmp_path.iterdir()]  # no video, no temporary


@pytest.mark.slow
def test_jaw_interrupted_while_jax_compiles(wagging, tmp_path):
    # no cache: whatever the session's cache holds, this process compiles
    argv = ["jaw", wagging, "--csv", tmp_path / "j.csv", "--method", "frame-fit",
            "--no-compile-cache"]
    status, err = _interrupt(tmp_path, "jax._src.compiler:backend_compile_and_load", argv,
                             signal.SIGINT, group=True)
    assert status == 130, err
    assert _messages(err) == ["cassi: interrupted"]
    assert not list(tmp_path.iterdir())


_CORPUS_CHILD = """
import sys
sys.path.insert(0, {here!r})
import types
from cassi_fit import cli
from cassi_fit.corpus import CorpusItem, run_corpus
import interrupt_tasks
module = types.ModuleType("cassi_fit._cli.block")
def register(subparsers):
    parser = subparsers.add_parser("block")
    parser.add_argument("out")
    parser.set_defaults(func=lambda args: run_corpus(
        interrupt_tasks.blocking_task, [CorpusItem("S1", f"t{{k}}", "") for k in range(4)],
        args.out, jobs=2, progress=False, compilation_cache=False) and 0)
module.register = register
sys.modules[module.__name__] = module
cli.SUBCOMMANDS = cli.SUBCOMMANDS + ("block",)
sys.exit(cli.main())
"""


@pytest.mark.parametrize("group", [True, False], ids=["ctrl-c-to-the-group", "sigterm"])
def test_corpus_run_interrupted_stops_its_workers(tmp_path, group):
    """Two workers each half-way through writing an output (they report it through a
    FIFO, then wait): Ctrl-C to the whole process group (the workers too), or SIGTERM to
    the parent alone. One line, status 130, no worker's traceback, no temporary file, and
    the workers gone."""
    fifo = tmp_path / "reached"
    os.mkfifo(fifo)
    out = tmp_path / "out"
    code = _CORPUS_CHILD.format(here=str(HERE))
    env = {**os.environ, "CASSI_TEST_REACHED": str(fifo)}
    proc = subprocess.Popen([sys.executable, "-c", code, "block", str(out)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, start_new_session=True)
    try:
        pids = _reports(fifo, proc, 2)
        if group:
            os.killpg(proc.pid, signal.SIGINT)
        else:
            os.kill(proc.pid, signal.SIGTERM)
        try:  # a guard, not a speed limit: a run that ignores the signal never ends
            _, err = proc.communicate(timeout=HANG_S)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            raise AssertionError(f"the run was still going {HANG_S} s after the signal") from None
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert err.splitlines() == ["cassi: interrupted"]
    assert [p.name for p in out.rglob("*") if p.is_file()] == []
    for pid in pids:  # the parent waited for its workers: they are gone
        assert not Path(f"/proc/{pid}").exists() or _zombie(pid)


def _reports(fifo: Path, proc: subprocess.Popen, n: int) -> list[int]:
    """The first ``n`` lines the workers write on ``fifo`` (their pids); an error if the
    run ends first (its stderr closes) instead of waiting for ever."""
    import select

    lines: list[str] = []
    fd = os.open(fifo, os.O_RDWR)  # read-write: never "closed" between two writers
    try:
        buffer = b""
        while len(lines) < n:
            ready, _, _ = select.select([fd, proc.stderr], [], [], HANG_S)
            if not ready:  # a guard, not a speed limit: the workers never reported
                raise AssertionError(f"no worker reported within {HANG_S} s")
            if fd not in ready:  # the run ended (or wrote an error) before reporting
                proc.wait()
                raise AssertionError(f"the run ended first: {proc.stderr.read()}")
            buffer += os.read(fd, 4096)
            *done, buffer = buffer.split(b"\n")
            lines += [d.decode() for d in done]
    finally:
        os.close(fd)
    return [int(line) for line in lines[:n]]


def _zombie(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z"
    except OSError:
        return True


def test_a_cli_run_as_a_function_returns_130_and_restores_the_handlers(tmp_path, capsys):
    from cassi_fit import cli

    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    code = cli.main(["jaw", str(tmp_path / "missing.txy"), "--csv", str(tmp_path / "o.csv")])
    assert code == 2  # an ordinary error: the function returns
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before
    assert textwrap.dedent(capsys.readouterr().err).startswith("cassi: error:")
