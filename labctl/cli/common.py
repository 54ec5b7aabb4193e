"""Shared CLI plumbing: one-line errors with exit 2, a single JSON object with --json."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
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
