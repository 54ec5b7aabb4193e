"""``labctl programme``: a protocol's specimens as separate campaigns, run one after another or on a Dask cluster,
give the same curves and the same stored results; the paper's programme is its 18 roller/rail campaigns."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from labctl.campaign import run_campaign
from labctl.programme import (
    CampaignJob,
    expected_impacts,
    paper_programme,
    paper_protocol_text,
    run_programme,
    specimen_jobs,
)
from labctl.protocol.parse import parse_protocol
from labctl.storage.reader import CampaignReader
from labctl.storage.records import CURVE_COLUMNS
from tests.cli_util import assert_one_line_error, labctl_here

TWO_SPECIMENS = """# two short specimens (a comment the split drops)
[protocol]
name = "pair"
description = "Two roller types, two 360° steps each"
version = 1

[[specimens]]
kind = "roller"
roller_type = 1
rail_ra_um = 0.2
max_load_n = 120.0
knob_step_deg = 360.0

[[specimens]]
kind = "roller"
roller_type = 7
rail_ra_um = 0.03
max_load_n = 120.0
knob_step_deg = 360.0

[acquisition]
samples = 16384
impacts_per_step = 2

[repetitions]
count = 2
"""


def _stored(path: str) -> list[dict[str, np.ndarray]]:
    with CampaignReader(path) as reader:
        return [c.columns() for c in reader.curves()]


def _same_curves(a, b) -> None:  # noqa: ANN001
    assert len(a) == len(b) > 0
    for x, y in zip(a, b, strict=True):
        x, y = (c if isinstance(c, dict) else c.columns() for c in (x, y))
        for col in CURVE_COLUMNS:
            np.testing.assert_array_equal(x[col], y[col], err_msg=col)


@pytest.fixture(scope="module")
def protocol_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("programme") / "pair.toml"
    path.write_text(TWO_SPECIMENS, encoding="utf-8")
    return path


def test_each_specimen_is_one_campaign_with_its_own_protocol(protocol_file, tmp_path):
    jobs = specimen_jobs(protocol_file, tmp_path, first_seed=5)
    assert [(j.name, Path(j.out).name, j.seed) for j in jobs] == [("pair_1", "pair_1.h5", 5),
                                                                   ("pair_2", "pair_2.h5", 6)]
    protos = [parse_protocol(j.protocol_text, j.name) for j in jobs]
    assert [p.specimens[0].roller_type for p in protos] == [1, 7]
    assert all(len(p.specimens) == 1 and p.repetitions.count == 2 and p.acquisition.samples == 16384
               and p.name == "pair" for p in protos)
    assert protos[1].specimens[0].rail_ra_m == pytest.approx(0.03e-6)
    # two 360° steps (preload, +81 N) below 120 N, two impacts each, two repetitions
    assert [expected_impacts(j) for j in jobs] == [8, 8]


def test_programme_on_a_cluster_equals_the_campaigns_run_one_after_another(protocol_file, tmp_path, capsys):
    from distributed import LocalCluster

    seq = labctl_here(capsys, "programme", str(protocol_file), "--out", str(tmp_path / "seq"), "--seed", "3",
                      "--workers", "0", "--json")
    assert seq.returncode == 0, seq.stderr
    # worker threads in this process keep the test quick; the tasks still go through the scheduler over TCP
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                      dashboard_address=None) as cluster:
        par = labctl_here(capsys, "programme", str(protocol_file), "--out", str(tmp_path / "par"), "--seed", "3",
                          "--scheduler", cluster.scheduler_address, "--json")
    assert par.returncode == 0, par.stderr
    a, b = json.loads(seq.stdout), json.loads(par.stdout)
    assert [c["status"] for c in a["campaigns"]] == [c["status"] for c in b["campaigns"]] == ["complete"] * 2
    assert [c["seed"] for c in b["campaigns"]] == [3, 4]
    assert all(c["identified_steps"] == 4 for c in b["campaigns"])
    for name in ("pair_1.h5", "pair_2.h5"):
        _same_curves(_stored(str(tmp_path / "seq" / name)), _stored(str(tmp_path / "par" / name)))
    # and equal to the campaign run directly with the same protocol text and seed
    job = specimen_jobs(protocol_file, tmp_path, first_seed=4)[1]
    direct = run_campaign(parse_protocol(job.protocol_text, "pair_2.toml"), out=tmp_path / "direct.h5", seed=4)
    _same_curves(direct.curves, _stored(str(tmp_path / "par" / "pair_2.h5")))


def test_a_failing_campaign_is_its_outcome_and_deleted_files_go(tmp_path):
    good = specimen_jobs("quick_check", tmp_path, first_seed=1)[0]
    good = CampaignJob(good.name, good.protocol_text.replace("samples = 65536", "samples = 16384"), good.out, 1,
                       keep_file=False)
    bad = CampaignJob("bad", "[protocol]\nname = 'bad'\n", str(tmp_path / "bad.h5"), 1)
    done = run_programme([bad, good], workers=0)
    assert [d.status for d in done] == ["failed", "complete"]
    assert "bad" in done[0].message and done[0].curves == ()
    assert len(done[1].curves) == 1 and len(done[1].curves[0].step) == 3
    assert not Path(good.out).exists() and not Path(bad.out).exists()


def test_paper_programme_is_nine_types_on_two_rails():
    jobs = paper_programme("/nowhere", seed=10)
    assert len(jobs) == 18 and jobs[0].name == "paper_type1_ra0.2" and jobs[0].seed == 10
    protos = [parse_protocol(j.protocol_text, j.name) for j in jobs]
    assert [(p.specimens[0].roller_type, round(p.specimens[0].rail_ra_m * 1e9)) for p in protos[:4]] == [
        (1, 200), (1, 30), (2, 200), (2, 30)]
    assert "roller type 4 on Ra 0.03 µm" in protos[7].description
    # the paper's programme is 3366 impacts: type 4 is capped at the protocol's 60 steps
    assert sum(expected_impacts(j) for j in jobs) == 3366
    with pytest.raises(Exception, match="roller_type = 1"):
        paper_protocol_text(2, 0.2e-6, base="[specimen]\nroller_type = 3\n")


def test_programme_refuses_bad_input_before_running(protocol_file, tmp_path, capsys):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "pair_2.h5").write_bytes(b"x")
    assert_one_line_error(labctl_here(capsys, "programme", str(protocol_file), "--out", str(tmp_path / "out"),
                                      "--workers", "0"), "pair_2.h5", "already exists")
    assert (tmp_path / "out" / "pair_2.h5").read_bytes() == b"x" and not (tmp_path / "out" / "pair_1.h5").exists()
    assert_one_line_error(labctl_here(capsys, "programme", "--out", str(tmp_path / "o2")), "nothing to run")
    assert_one_line_error(labctl_here(capsys, "programme", "quick_check", "--out", str(tmp_path / "o3"),
                                      "--workers", "-1"), "--workers")
    assert_one_line_error(labctl_here(capsys, "programme", str(tmp_path / "none.toml"), "--out", str(tmp_path)),
                          "none.toml")
    assert_one_line_error(labctl_here(capsys, "programme", "quick_check", "quick_check", "--out", str(tmp_path)),
                          "quick_check")
