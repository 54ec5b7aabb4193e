"""The README's scripting example runs as documented and produces a readable stiffness table."""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

from labctl.stiffness_table import read_stiffness_table

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "scripted_campaign.py"


def test_scripted_campaign_example(tmp_path, capsys, monkeypatch):
    # ``python examples/scripted_campaign.py OUT`` in this process: the script as __main__, its argv and cwd
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", [str(EXAMPLE), str(tmp_path / "out")])
    try:
        runpy.run_path(str(EXAMPLE), run_name="__main__")
        code = 0
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "campaign complete" in out.out and out.out.count("bounce") == 3
    points = read_stiffness_table(tmp_path / "out" / "stiffness.csv")
    assert len(points) == 3 and all(p.stiffness_n_per_m > 1e7 for p in points)
