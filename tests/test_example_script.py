"""The README's scripting example runs as documented and produces a readable stiffness table."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from labctl.stiffness_table import read_stiffness_table

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "scripted_campaign.py"


def test_scripted_campaign_example(tmp_path):
    proc = subprocess.run([sys.executable, str(EXAMPLE), str(tmp_path / "out")], capture_output=True, text=True,
                          timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "campaign complete" in proc.stdout and proc.stdout.count("bounce") == 3
    points = read_stiffness_table(tmp_path / "out" / "stiffness.csv")
    assert len(points) == 3 and all(p.stiffness_n_per_m > 1e7 for p in points)
