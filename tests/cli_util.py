"""Run ``labctl`` as a user would: in this process by default (the same ``main`` the console script calls, the same
argv, stdout, stderr and exit code, without a second of interpreter and import start-up per call), or as a true
subprocess where a test needs one (start-up, signals, a fresh interpreter): ``labctl_process``."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import traceback
from typing import Any


def labctl(*args: str, timeout: float = 300, cwd: str | None = None) -> subprocess.CompletedProcess[str]:
    """``labctl ARGS`` in this process: stdout and stderr captured, stdin at end of file, the working directory
    ``cwd`` for the call, signal handlers and the working directory restored after it. An uncaught exception
    prints its traceback on stderr and exits 1, as the console script would. ``timeout`` is left to pytest."""
    from labctl.cli import main

    out, err = io.StringIO(), io.StringIO()
    here, sigint = os.getcwd(), signal.getsignal(signal.SIGINT)
    stdin = sys.stdin
    try:
        if cwd is not None:
            os.chdir(cwd)
        sys.stdin = io.StringIO("")
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(args))
            except SystemExit as exc:  # argparse usage errors, --help, --version
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
                if not isinstance(exc.code, int | None):
                    err.write(f"{exc.code}\n")
            except Exception:  # noqa: BLE001 — what the interpreter does with an uncaught exception
                traceback.print_exc(file=err)
                code = 1
    finally:
        sys.stdin = stdin
        os.chdir(here)
        signal.signal(signal.SIGINT, sigint)
    return subprocess.CompletedProcess(["labctl", *args], int(code), out.getvalue(), err.getvalue())


def labctl_process(*args: str, timeout: float = 300, cwd: str | None = None) -> subprocess.CompletedProcess[str]:
    """The installed ``labctl`` console script in a subprocess (a fresh interpreter)."""
    exe = shutil.which("labctl")
    cmd = [exe, *args] if exe else [sys.executable, "-m", "labctl", *args]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd, env=env)


def shipped_environment(**extra: str) -> dict[str, str]:
    """This process's environment without the tests' own frame rate (``TEXTUAL_FPS``, set in conftest), plus
    ``extra``: a labctl started with it draws at the rate labctl ships."""
    return {**{k: v for k, v in os.environ.items() if k != "TEXTUAL_FPS"}, **extra}


def labctl_json(*args: str, **kw: Any) -> dict[str, Any]:
    return one_json_object(labctl(*args, "--json", **kw))


def one_json_object(proc: subprocess.CompletedProcess[str]) -> dict[str, Any]:
    """The single JSON object a successful ``--json`` run printed."""
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected exactly one JSON line, got: {proc.stdout!r}"
    out = json.loads(lines[0])
    assert isinstance(out, dict)
    return out


def assert_one_line_error(proc: subprocess.CompletedProcess[str], *fragments: str) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for frag in fragments:
        assert frag in lines[0], lines[0]
    return lines[0]


def labctl_here(capsys: Any, *args: str) -> subprocess.CompletedProcess[str]:
    """Run a command in this process (no interpreter start-up); same exit code and streams as ``labctl``."""
    from labctl.cli import main

    capsys.readouterr()
    try:
        code = main(list(args))
    except SystemExit as exc:  # argparse usage errors
        code = int(exc.code or 0)
    out = capsys.readouterr()
    return subprocess.CompletedProcess(["labctl", *args], code, out.out, out.err)


def labctl_here_json(capsys: Any, *args: str) -> dict[str, Any]:
    return one_json_object(labctl_here(capsys, *args, "--json"))
