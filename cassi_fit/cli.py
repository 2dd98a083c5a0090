"""The ``cassi`` command line.

Each subcommand lives in its own module under ``cassi_fit/_cli/`` and exposes
``register(subparsers)``, which adds its parser (cheaply: no heavy imports) and sets
``func=run``. ``run(args)`` does the work and returns an exit code (0 on success).

Errors: a :class:`~cassi_fit.errors.CassiError` (and any other exception) is printed as one
line, ``cassi: error: ...``, with exit code 2 (1 for unexpected exceptions); the
traceback is shown only with ``--debug``. Ctrl-C (SIGINT) and SIGTERM at any moment print
``cassi: interrupted`` and exit 130: the command turns them into ``KeyboardInterrupt``
where that is safe (``cassi_fit._signals.interruptible``), so that every writer removes its
temporary files, ffmpeg and the corpus workers are stopped and the OpenGL context is
released; the program then ends without the interpreter's shutdown (``os._exit``), where
JAX's and Mesa's threads could crash it. A closed output pipe exits 141 quietly.

Compilation: the commands that compute keep what JAX compiles in the persistent
compilation cache (``cassi_fit.corpus._process``: ``CASSI_COMPILE_CACHE=DIR|off``, else
``JAX_COMPILATION_CACHE_DIR``, else ``$XDG_CACHE_HOME/cassi_fit/jax`` or
``~/.cache/cassi_fit/jax``), so a second run loads instead of compiling, and the slowest
kernels to trace exported beside it (``cassi_fit._exported``; ``CASSI_EXPORT_CACHE=DIR|off``);
``--no-compile-cache`` turns both off for one command.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

# (module under cassi_fit._cli, one-line help). Order = order in --help.
#: Subcommands that do not compute with JAX (no compilation cache, no --no-compile-cache).
NO_JAX = ("info", "synth")
SUBCOMMANDS = (
    "demo",
    "info",
    "synth",
    "jaw",
    "animate",
    "export",
    "view",
    "calibrate",
    "evaluate",
    "acoustics",
)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The ``cassi`` parser with every subcommand, or with the subcommand ``only`` alone
    (:func:`_parse`: the command given; its module is the only one imported)."""
    parser = argparse.ArgumentParser(
        prog="cassi",
        description=(
            "cassi_fit: animate a 3D Parke-style face with tongue, teeth and palate from "
            "X-ray microbeam pellet data (after CASSI, Scheidt & Hamilton 1999), and fit "
            "jaw rotation by the paper's closed form or by least squares."
        ),
    )
    parser.epilog = (
        "JAX runs on the CPU: the command sets JAX_PLATFORMS=cpu for itself unless "
        "JAX_PLATFORMS is already set (e.g. JAX_PLATFORMS=cuda to use a GPU). Importing "
        "cassi_fit as a library leaves that choice to you. What JAX compiles is kept in "
        "$CASSI_COMPILE_CACHE (a folder, or 'off'), else $JAX_COMPILATION_CACHE_DIR, else "
        "$XDG_CACHE_HOME/cassi_fit/jax (~/.cache/cassi_fit/jax), so that the next command "
        "loads it instead of compiling again; the slowest kernels to trace are kept in its "
        "exported/ ($CASSI_EXPORT_CACHE: a folder, or 'off'). Ctrl-C or SIGTERM: exit "
        "status 130."
    )
    parser.add_argument(
        "--debug", action="store_true", help="show the full traceback when something fails"
    )
    parser.add_argument("--no-compile-cache", action="store_true", help=_NO_CACHE_HELP)
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMANDS if only is None else (only,):
        try:
            module = importlib.import_module(f"cassi_fit._cli.{name}")
        except ModuleNotFoundError as exc:  # a subcommand not (yet) installed
            if exc.name != f"cassi_fit._cli.{name}":
                raise
            continue
        module.register(subparsers)
    for name, sub in subparsers.choices.items():
        if name not in NO_JAX:  # also after the command's name; SUPPRESS: no default
            sub.add_argument("--no-compile-cache", action="store_true",
                             default=argparse.SUPPRESS, help=_NO_CACHE_HELP)
    return parser


_NO_CACHE_HELP = ("compile everything afresh and keep nothing (default: JAX's persistent "
                  "compilation cache, see 'cassi --help')")


def _one_line_warnings() -> None:
    """Warnings as the user reads them: ``cassi: warning: <message>``, one line (not
    Python's ``file:line: Category: message`` and a source line)."""
    import warnings

    def show(message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split()) or category.__name__
        print(f"cassi: warning: {text}", file=file or sys.stderr)

    warnings.showwarning = show


def main(argv: list[str] | None = None) -> int:
    """Run the ``cassi`` command with ``argv`` (default: the process's arguments); the
    exit status. ``argv`` None is the program itself: after an interruption (or a signal
    while it exits) the process ends at once with status 130 (see the module's doc);
    with an ``argv`` list, as from Python, 130 is returned."""
    from ._signals import INTERRUPT_EXIT_STATUS, exit_on_signal, interruptible

    program = argv is None
    if program:  # what a signal does outside the command's own handling: end at once
        exit_on_signal()
        _one_line_warnings()  # the program's own output (a caller's warnings stay its own)
        _freeze_heap_at_exit()
    args = None
    try:
        with interruptible():  # before anything else: parsing may be interrupted too
            args = _parse(argv)
            status = 2 if args is None else int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("cassi: interrupted", file=sys.stderr)
        status = INTERRUPT_EXIT_STATUS
    except BrokenPipeError:  # e.g. `cassi info DATA | head`: the reader left; say nothing
        _silence_stdout()
        status = 141
    except Exception as exc:  # one line for the user; the traceback only under --debug
        if args is not None and args.debug:
            raise
        from .errors import CassiError

        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if not isinstance(exc, CassiError):
            message = f"{type(exc).__name__}: {message}"
        print(f"cassi: error: {message}", file=sys.stderr)
        status = 2 if isinstance(exc, CassiError) else 1
    if program and status == INTERRUPT_EXIT_STATUS:
        from ._signals import _flush_and_exit

        _flush_and_exit(status, None)  # no interpreter shutdown after an interrupt
    return status


def _freeze_heap_at_exit() -> None:
    """At the program's exit, before the interpreter's last garbage collections, every
    object then alive moved out of their way (``gc.freeze``): those collections walk the
    whole heap, JAX's modules and the run's (about 220 000 objects after ``cassi
    animate``), for garbage a finished command leaves none of: 0.5 s of CPU and up to a
    second of a busy machine's wall time (``benchmarks/bench_realtime.py``'s exit row).
    The program only: a caller of :func:`main` from Python is unchanged."""
    import atexit
    import gc

    atexit.register(gc.freeze)


def _parse(argv: list[str] | None) -> argparse.Namespace | None:
    """The parsed command line, with the process set up for it (JAX on the CPU unless
    chosen, the compilation cache); None (after printing the help) if no command."""
    # The command (not the library) picks the CPU, before anything imports JAX, so that
    # JAX does not probe for accelerators; a platform the user set wins.
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
    parser = build_parser(_command_named(sys.argv[1:] if argv is None else argv))
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return None
    if args.command not in NO_JAX:
        from .corpus._process import default_compile_cache, use_compile_cache

        use_compile_cache(None if args.no_compile_cache else default_compile_cache())
    return args


def _command_named(argv: list[str]) -> str | None:
    """The subcommand ``argv`` names: its first word, after none but the program's own
    ``--debug`` and ``--no-compile-cache`` (or what argparse takes for them); None for
    anything else (no command, not a subcommand, ``--help`` or an unknown option before
    it: the whole parser then answers as ever)."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in SUBCOMMANDS else None
        if not (len(word) > 2 and any(o.startswith(word) for o in _OWN_OPTIONS)):
            return None
    return None


#: The program's options that may come before the command (argparse also takes prefixes).
_OWN_OPTIONS = ("--debug", "--no-compile-cache")


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that Python's flush at exit does not fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
