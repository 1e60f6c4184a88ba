"""The `lirm` command line: the parser, and what an error becomes (a sentence and an exit code). Each
subcommand maps onto a dataclass config; only built features appear. The commands themselves are in
engine/commands/, one module per command."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
from pathlib import Path

from lirm.renderer.context import GLContextError

from . import progress_events
from .commands import app, bench, capture, curve, demo, export, fetch, reconstruct, refine, render, ship, suggest, train
from .commands import train_materials
from .commands import eval as eval_
from .errors import LirmResourceError, LirmUsageError, LirmUserError

# The commands in the order `lirm --help` lists them; each is a module of engine/commands/.
COMMANDS = (app, demo, render, capture, reconstruct, refine, export, suggest, train, train_materials, curve, eval_, ship, bench, fetch)

# Exit codes (README "Exit codes"): what went wrong, for scripts and for the app's background jobs.
EXIT_OK = 0  # done
EXIT_NOTHING_USABLE = 1  # the run finished but produced nothing usable (e.g. no photo could be posed)
EXIT_USAGE = 2  # bad usage: an unknown or missing argument, an option value out of its range
EXIT_INPUT = 3  # bad input: a file, folder, capture or checkpoint that cannot be used, or a missing prerequisite
EXIT_RESOURCES = 4  # not enough memory or disk for what was asked
EXIT_INTERNAL = 70  # an internal error: a bug (sysexits.h EX_SOFTWARE)
EXIT_CANCELLED = 130  # cancelled with Ctrl-C (128 + SIGINT)

# The options to lower when a command runs out of memory all the same.
MEMORY_OPTIONS = {
    "capture": ("--max-side", "--size"), "reconstruct": ("--render-size", "--grid-resolution", "--views-per-update"),
    "refine": ("--render-size", "--grid-resolution", "--preset"), "export": ("--grid", "--texture"),
    "render": ("--size", "--supersample"), "eval": ("--size", "--objects", "--mesh-resolution"),
    "train": ("--preset", "--workers"), "bench model": ("--preset", "--views-per-update"), "bench capacity": ("--preset",),
    "bench export": ("--grid", "--texture"), "bench trajectory": ("--size", "--mesh-resolution"),
    "bench refine": ("--size", "--objects"), "bench update-order": ("--size",), "bench synth": ("--size", "--views"),
    "bench render": ("--sizes",), "bench capture": ("--max-side", "--counts"),
}


def listen_for_cancel() -> None:
    """The app cancels its background jobs with SIGINT. A process started from the background of a
    non-interactive shell (a script's `cmd &`, CI) inherits SIGINT ignored, and Python then installs no
    KeyboardInterrupt handler, so the app's Cancel would be lost and the job only killed when its grace
    ran out, losing the best state so far. A command the app runs always listens."""
    if progress_events.enabled() and signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def main(argv: list[str] | None = None) -> int:
    listen_for_cancel()
    parser = build_parser()
    args = parser.parse_args(argv)  # bad usage: argparse prints it and exits with EXIT_USAGE (2)
    _configure_logging(args.verbose)
    for stream in (sys.stdout, sys.stderr):  # a log file sees each line when it is printed, not at exit
        if hasattr(stream, "reconfigure") and not stream.isatty():
            try:
                stream.reconfigure(line_buffering=True)
            except (ValueError, OSError):
                pass
    try:
        return args.run(args)
    except LirmUsageError as err:
        print(f"error: {err} (see `lirm {args.command} --help`)", file=sys.stderr)
        return EXIT_USAGE
    except LirmResourceError as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_RESOURCES
    except (LirmUserError, GLContextError) as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print("cancelled", file=sys.stderr)
        return EXIT_CANCELLED
    except Exception as err:  # noqa: BLE001 - the last line of defence: a sentence, never a bare traceback
        if _out_of_memory(err):
            print(f"error: {_out_of_memory_sentence(args, err)}", file=sys.stderr)
            return EXIT_RESOURCES
        import traceback

        crash = _write_crash_report(sys.argv[1:] if argv is None else argv)
        if args.verbose or crash is None:
            traceback.print_exc()
        where = f"the traceback written to {crash}" if crash else "the traceback above"
        print(f"error: internal error: {type(err).__name__}: {err}; this is a bug in LIRM Studio: please report it "
              f"with {where}", file=sys.stderr)
        return EXIT_INTERNAL


def _out_of_memory(err: BaseException) -> bool:
    """A MemoryError, or torch's (CPU or CUDA) allocation failure, which is a RuntimeError."""
    if isinstance(err, MemoryError):
        return True
    text = str(err).lower()
    return isinstance(err, RuntimeError) and ("out of memory" in text or "can't allocate memory" in text)


def _out_of_memory_sentence(args: argparse.Namespace, err: BaseException) -> str:
    from .resources import available_memory_bytes, format_bytes

    options = [o for o in MEMORY_OPTIONS.get(args.command, ()) if hasattr(args, o.lstrip("-").replace("-", "_"))]
    now = [f"{o} (now {getattr(args, o.lstrip('-').replace('-', '_'))})" for o in options]
    free = available_memory_bytes()
    lower = (f"lower {', '.join(now[:-1])} or {now[-1]}" if len(now) > 1 else f"lower {now[0]}") if now else \
        "run it on a machine with more memory"
    return (f"not enough memory: `lirm {args.command}` ran out of memory ({type(err).__name__})"
            + (f" with {format_bytes(free)} free now" if free is not None else "")
            + f"; {lower}, or close other programs, and run it again")


def _write_crash_report(argv: list[str]) -> Path | None:
    """The traceback of the exception being handled, in CACHE/lirm/crash-<time>.txt (CACHE: $XDG_CACHE_HOME,
    else ~/.cache; the system's temporary folder when neither can be written); None when nothing can."""
    import os
    import platform
    import tempfile
    import time
    import traceback

    try:
        from importlib.metadata import version

        lirm_version = version("lirm")
    except Exception:  # noqa: BLE001 - not installed as a distribution
        lirm_version = "unknown"
    text = (f"lirm {lirm_version}, Python {platform.python_version()} on {platform.platform()}\n"
            f"command: lirm {' '.join(argv)}\ntime: {time.strftime('%Y-%m-%d %H:%M:%S')}\n\n{traceback.format_exc()}")
    from .io.user_cache import user_cache_folder

    stamp = f"crash-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
    for folder in (user_cache_folder(), Path(tempfile.gettempdir()) / "lirm"):
        try:
            folder.mkdir(parents=True, exist_ok=True)
            for n in range(100):  # never overwrite an earlier report
                path = folder / (stamp + (f"-{n}" if n else "") + ".txt")
                try:
                    with open(path, "x", encoding="utf-8") as f:
                        f.write(text)
                    return path
                except FileExistsError:
                    continue
        except OSError:
            continue
    return None


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="lirm", description="LIRM Studio: photos of an object to a relightable 3D asset.")
    parser.add_argument("-v", "--verbose", action="store_true", help="more logging")
    parser.add_argument("--version", action="version", version=f"lirm (LIRM Studio) {_version()}")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)
    for command in COMMANDS:
        command.add_parser(sub)
    for name, command in sub.choices.items():  # for messages: `lirm COMMAND --help`
        command.set_defaults(command=name)
    return parser


def _configure_logging(verbose: bool) -> None:
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
    log = logging.getLogger("lirm")
    log.handlers[:] = [handler]
    log.setLevel(logging.DEBUG if verbose else logging.INFO)
    log.propagate = False


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("lirm")
    except PackageNotFoundError:
        return "unknown (not installed)"


if __name__ == "__main__":
    sys.exit(main())
