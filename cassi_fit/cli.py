"""The ``cassi`` command line.

Each subcommand lives in its own module under ``cassi_fit/_cli/`` and exposes
``register(subparsers)``, which adds its parser (cheaply: no heavy imports) and sets
``func=run``. ``run(args)`` does the work and returns an exit code (0 on success).

Errors: a :class:`~cassi_fit.errors.CassiError` (and any other exception) is printed as one
line, ``cassi: error: ...``, with exit code 2 (1 for unexpected exceptions); the
traceback is shown only with ``--debug``. Ctrl-C and SIGTERM (which the command turns into
``KeyboardInterrupt``, so that every writer removes its temporary files) print
``cassi: interrupted`` and exit 130; a closed output pipe exits 141 quietly.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

# (module under cassi_fit._cli, one-line help). Order = order in --help.
SUBCOMMANDS = (
    "demo",
    "info",
    "synth",
    "jaw",
    "animate",
    "export",
    "calibrate",
    "evaluate",
)


def build_parser() -> argparse.ArgumentParser:
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
        "cassi_fit as a library leaves that choice to you."
    )
    parser.add_argument(
        "--debug", action="store_true", help="show the full traceback when something fails"
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMANDS:
        try:
            module = importlib.import_module(f"cassi_fit._cli.{name}")
        except ModuleNotFoundError as exc:  # a subcommand not (yet) installed
            if exc.name != f"cassi_fit._cli.{name}":
                raise
            continue
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    # The command (not the library) picks the CPU, before anything imports JAX, so that
    # JAX does not probe for accelerators; a platform the user set wins.
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    from ._io import terminate_as_interrupt

    try:
        with terminate_as_interrupt():  # SIGTERM cleans up as Ctrl-C does
            return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("cassi: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `cassi info DATA | head`: the reader left; say nothing
        _silence_stdout()
        return 141
    except Exception as exc:  # one line for the user; the traceback only under --debug
        if args.debug:
            raise
        from .errors import CassiError

        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if not isinstance(exc, CassiError):
            message = f"{type(exc).__name__}: {message}"
        print(f"cassi: error: {message}", file=sys.stderr)
        return 2 if isinstance(exc, CassiError) else 1


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that Python's flush at exit does not fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
