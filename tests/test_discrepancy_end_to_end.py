"""End to end: campaigns on the simulated rig with a hidden world effect, processed from raw impacts, then the
discrepancy workflow names the effect; a world without one gets none."""

from __future__ import annotations

import pytest

from tests.cli_util import labctl, labctl_json

PROTOCOL = """
[protocol]
name = "two_lengths"
description = "Roller types 2 and 4: short and long rollers, so length-dependent effects show"

[[specimens]]
roller_type = 2
rail_ra_um = 0.2

[[specimens]]
roller_type = 4
rail_ra_um = 0.2

[loading]
max_steps = 7
settle_poll_s = 0.0

[acquisition]
samples = 16384
impacts_per_step = 1

[repetitions]
count = 2
"""


@pytest.mark.slow
@pytest.mark.parametrize(("world", "effect"), [("misalignment", "misalignment"), ("tripp_only", None)])
def test_hidden_world_effect_is_named_from_raw_impacts(tmp_path, world, effect):
    proto = tmp_path / "two_lengths.toml"
    proto.write_text(PROTOCOL)
    campaign = tmp_path / f"{world}.h5"
    run = labctl("run", str(proto), "--backend", "sim", "--world", world, "--seed", "11", "--out", str(campaign),
                 "--quiet", timeout=600)
    assert run.returncode == 0, run.stderr
    table = tmp_path / f"{world}.csv"
    proc = labctl("process", str(campaign), "--csv", str(table))
    assert proc.returncode == 0, proc.stderr
    for measured in (table, campaign):
        out = labctl_json("discrepancy", str(measured))
        names = [e["name"] for e in out["effects"]]
        if effect is None:
            assert names == [], out["effects"]
        else:
            assert names[:1] == [effect], out["effects"]
            assert out["gap_after"] < out["gap_before"]
