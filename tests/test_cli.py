"""The `cassi` dispatcher: help, one-line errors, tracebacks only under --debug."""

import sys
import types

import pytest

from cassi_fit import cli
from cassi_fit.errors import DataFormatError


@pytest.fixture
def failing_command(monkeypatch):
    """A throwaway subcommand `boom` whose run raises what the test asks for."""
    module = types.ModuleType("cassi_fit._cli.boom")
    state = {}

    def register(subparsers):
        p = subparsers.add_parser("boom", help="fails on purpose")
        p.set_defaults(func=lambda args: (_ for _ in ()).throw(state["exc"]))

    module.register = register
    monkeypatch.setitem(sys.modules, "cassi_fit._cli.boom", module)
    monkeypatch.setattr(cli, "SUBCOMMANDS", cli.SUBCOMMANDS + ("boom",))
    return state


def test_no_command_prints_help(capsys):
    assert cli.main([]) == 2
    assert "usage: cassi" in capsys.readouterr().out


def test_every_subcommand_has_help(capsys):
    parser = cli.build_parser()
    names = parser._subparsers._group_actions[0].choices  # argparse has no public accessor
    assert {"info", "synth", "jaw", "animate", "demo"} <= set(names)
    for name in names:
        with pytest.raises(SystemExit) as exit_info:
            cli.main([name, "--help"])
        assert exit_info.value.code == 0
        assert "usage: cassi" in capsys.readouterr().out


def _help_of(parser, argv, capsys) -> str:
    with pytest.raises(SystemExit) as exit_info:
        parser.parse_args(argv)
    assert exit_info.value.code == 0
    return capsys.readouterr().out


def test_the_command_parses_with_its_own_subcommand_alone(capsys):
    """``cassi COMMAND ...`` builds the parser with that subcommand only (its module alone
    imported): the same help and options as the whole parser's; anything else before the
    command than ``--debug`` and ``--no-compile-cache`` (``--help`` first) gets the whole
    parser."""
    whole = cli.build_parser()
    for name in whole._subparsers._group_actions[0].choices:
        assert cli._command_named(["--debug", name, "x"]) == name
        assert (_help_of(cli.build_parser(name), [name, "--help"], capsys)
                == _help_of(whole, [name, "--help"], capsys))
    for argv in ([], ["--help", "jaw"], ["-h"], ["nothing"], ["--debug=1", "jaw"], ["--", "jaw"],
                 ["-", "jaw"], ["--verbose", "jaw"]):
        assert cli._command_named(argv) is None, argv
    assert cli._command_named(["--deb", "--no-compile", "jaw"]) == "jaw"  # argparse's prefixes


def test_toolkit_error_is_one_line(failing_command, capsys):
    failing_command["exc"] = DataFormatError("S01/TP005.TXY", 12, "expected 17 fields, found 16")
    assert cli.main(["boom"]) == 2
    err = capsys.readouterr().err
    assert err == "cassi: error: S01/TP005.TXY:12: expected 17 fields, found 16\n"


def test_unexpected_error_is_one_line_and_debug_shows_traceback(failing_command, capsys):
    failing_command["exc"] = RuntimeError("first line\nsecond line")
    assert cli.main(["boom"]) == 1
    assert capsys.readouterr().err == "cassi: error: RuntimeError: first line\n"
    with pytest.raises(RuntimeError):
        cli.main(["--debug", "boom"])


def test_sigterm_cleans_up_like_ctrl_c(monkeypatch, tmp_path, capsys):
    """SIGTERM mid-write: exit 130, no temporary file left (the writer's clean-up ran)."""
    import os
    import signal

    from cassi_fit._io import atomic_write

    def not_converted(signum, frame):  # what runs if cli.main does not convert SIGTERM
        raise RuntimeError("SIGTERM reached the previous handler")

    previous = signal.signal(signal.SIGTERM, not_converted)
    module = types.ModuleType("cassi_fit._cli.slow")

    def write(fh):
        fh.write("half")
        os.kill(os.getpid(), signal.SIGTERM)
        raise AssertionError("SIGTERM did not stop the write")  # os.kill runs the handler

    def register(subparsers):
        p = subparsers.add_parser("slow", help="writes slowly")
        p.set_defaults(func=lambda args: atomic_write(tmp_path / "out.txt", write))

    module.register = register
    monkeypatch.setitem(sys.modules, "cassi_fit._cli.slow", module)
    monkeypatch.setattr(cli, "SUBCOMMANDS", cli.SUBCOMMANDS + ("slow",))
    try:
        assert cli.main(["slow"]) == 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert capsys.readouterr().err == "cassi: interrupted\n"
    assert list(tmp_path.iterdir()) == []
    assert signal.getsignal(signal.SIGTERM) is previous


def test_broken_pipe_is_quiet(failing_command, capsys):
    failing_command["exc"] = BrokenPipeError(32, "Broken pipe")
    assert cli.main(["boom"]) == 141
    assert capsys.readouterr().err == ""
