"""Shared CLI plumbing: one-line errors with exit 2, a single JSON object with --json."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from labctl.errors import LabctlError

EXIT_USAGE = 2


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist") and hasattr(value, "dtype"):  # numpy arrays and scalars, without importing numpy
        return _plain(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def emit(result: dict[str, Any], as_json: bool, text: Callable[[dict[str, Any]], str]) -> None:
    """Print a command's result: exactly one JSON object, or the human-readable text."""
    if as_json:
        sys.stdout.write(json.dumps(_plain(result)) + "\n")
    else:
        sys.stdout.write(text(result).rstrip("\n") + "\n")


def fail(command: str, message: str) -> int:
    first = " ".join(str(message).split())
    sys.stderr.write(f"labctl {command}: error: {first}\n")
    return EXIT_USAGE


def run_command(args: argparse.Namespace) -> int:
    """Call the command's function; user errors become one line on stderr and exit 2."""
    name = getattr(args, "command", "labctl")
    try:
        code = args.func(args)
    except KeyboardInterrupt:
        sys.stderr.write(f"labctl {name}: interrupted\n")
        return 130
    except (LabctlError, ValueError, OSError) as exc:
        return fail(name, str(exc) or type(exc).__name__)
    return int(code or 0)


def add_json(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")


@contextmanager
def step_bar(what: str, quiet: bool = False) -> Iterator[Callable[[int, int], None]]:
    """A progress bar on stderr (tqdm) fed by ``progress(done, total)`` callbacks.

    Silent with ``quiet`` and when stderr is not a terminal (logs and pipes get only the result)."""
    bar: Any = None

    def progress(done: int, total: int) -> None:
        nonlocal bar
        if quiet or not (hasattr(sys.stderr, "isatty") and sys.stderr.isatty()):
            return
        if bar is None:
            from tqdm import tqdm

            bar = tqdm(total=total, desc=f"labctl {what}", unit="step", file=sys.stderr, mininterval=0.5,
                       dynamic_ncols=True)
        bar.update(done - bar.n)

    try:
        yield progress
    finally:
        if bar is not None:
            bar.close()


def say(message: str) -> None:
    """A progress line on stderr before a long silent stretch, for a person at a terminal only (scripts and
    ``--json`` readers see stderr stay empty or hold just the one-line error)."""
    if sys.stderr.isatty():
        sys.stderr.write(message.rstrip("\n") + "\n")
        sys.stderr.flush()
