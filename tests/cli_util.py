"""Run the installed ``labctl`` console script as a user would."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from typing import Any


def labctl(*args: str, timeout: float = 300, cwd: str | None = None) -> subprocess.CompletedProcess[str]:
    exe = shutil.which("labctl")
    cmd = [exe, *args] if exe else [sys.executable, "-m", "labctl", *args]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd, env=env)


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
