"""End to end: campaigns on the simulated rig whose world hides its contact law in a form the discrepancy library
does not share (a table of k(F) per roller type), processed from raw impacts, then the discrepancy workflow names
the effect the table hides; a world without one gets none."""

from __future__ import annotations

import numpy as np
import pytest

from tests.cli_util import labctl_here, labctl_here_json

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

ROLLERS = {2: (1.5e-3, 1.104e-3), 4: (9.0e-3, 8.309e-3)}  # type: (D, L_we), Table 1
EDGE_M = 0.15e-3  # the rail beyond each roller end that carries load: what the table hides


def line_contact_with_end_zones(load_n: np.ndarray, diameter_m: float, length_m: float) -> np.ndarray:
    """An independent statement of the truth (not labctl's code): steel roller between steel rails, rails taken
    to 3 mm depth (Tripp, plane strain), with the contact carried over L_we + 2·EDGE_M."""
    e_star = 1.0 / (2.0 * (1 - 0.29**2) / 210e9)
    radius = diameter_m / 2
    p = load_n / length_m
    a = np.sqrt(4 * p * radius / (np.pi * e_star))
    per_length = (2 / (np.pi * e_star) * (np.log(4 * radius / a) - 1)
                  + 1 / (np.pi * e_star) * (2 * np.log(2 * 3e-3 / a) - 0.29 / 0.71 - 1))
    return (length_m + 2 * EDGE_M) / per_length


def table_world(path) -> None:
    loads = np.geomspace(30.0, 8000.0, 30)
    lines = ['description = "measured k(F) of types 2 and 4, tabulated"', "[baseline]", 'model = "table"']
    for type_id, (d, length) in ROLLERS.items():
        k = line_contact_with_end_zones(loads, d, length)
        lines += ["[[baseline.tables]]", f"roller_type = {type_id}",
                  "load_n = [" + ", ".join(f"{x:.6g}" for x in loads) + "]",
                  "stiffness_n_per_m = [" + ", ".join(f"{x:.6g}" for x in k) + "]"]
    lines += ["[instruments]", "contact_nonlinearity = 0.0"]  # a table gives k, not its nonlinear dynamics
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.slow
@pytest.mark.parametrize(("world", "effect"), [("table", "end_effects"), ("tripp_only", None)])
def test_hidden_world_effect_is_named_from_raw_impacts(tmp_path, capsys, world, effect):
    proto = tmp_path / "two_lengths.toml"
    proto.write_text(PROTOCOL)
    if world == "table":
        world = str(tmp_path / "table.toml")
        table_world(tmp_path / "table.toml")
    campaign = tmp_path / "campaign.h5"
    run = labctl_here(capsys, "run", str(proto), "--backend", "sim", "--world", world, "--seed", "11", "--out",
                      str(campaign), "--quiet")
    assert run.returncode == 0, run.stderr
    table = tmp_path / "stiffness.csv"
    proc = labctl_here(capsys, "process", str(campaign), "--csv", str(table))
    assert proc.returncode == 0, proc.stderr
    for measured in (table, campaign):
        out = labctl_here_json(capsys, "discrepancy", str(measured))
        names = [e["name"] for e in out["effects"]]
        if effect is None:
            assert names == [], out["effects"]
        else:
            assert set(names) <= {effect}, out["effects"]
            assert any(x["explanation"] == effect for x in out["explanations"][:3]), out["explanations"][:3]
            if names:
                assert out["gap_after"] < out["gap_before"]
                edge = out["effects"][0]["parameters"]["edge_length_m"]
                assert edge == pytest.approx(EDGE_M, rel=0.3), out["effects"]  # the size the table hides
            else:  # two roller geometries: the verdict says what the design cannot separate
                assert any("2 roller geometries" in r for r in out["decision"]["identifiability"])
