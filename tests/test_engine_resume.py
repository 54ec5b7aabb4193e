"""Resume describes the whole campaign; bad inputs are refused before a campaign file exists."""

from __future__ import annotations

from labctl import events as ev
from labctl.campaign import run_campaign
from labctl.engine import RunControl
from tests.cli_util import assert_one_line_error, labctl_here, labctl_here_json
from tests.engine_util import SHORT


def _protocol(tmp_path):  # noqa: ANN001, ANN202
    path = tmp_path / "short.toml"
    path.write_text(SHORT.format(max_load=120.0, step=360.0, samples=8192, impacts=2, reps=2))
    return path


def test_resume_reports_every_repetition_and_a_complete_file_has_nothing_left(tmp_path, capsys):
    proto, out = _protocol(tmp_path), tmp_path / "c.h5"
    control = RunControl()

    def stop_after_first_repetition(event: ev.Event) -> None:
        if isinstance(event, ev.RunProcessed):
            control.stop()

    first = run_campaign(proto, out=out, seed=2, control=control, subscribers=[stop_after_first_repetition])
    assert first.status == "interrupted" and [(c.series, c.run) for c in first.curves] == [(1, 1)]
    again = run_campaign(proto, out=out, resume=True)
    assert again.status == "complete" and [(c.series, c.run) for c in again.curves] == [(1, 1), (1, 2)]
    assert again.curves[0].load_n.tolist() == first.curves[0].load_n.tolist()
    done = labctl_here_json(capsys, "run", str(proto), "--out", str(out), "--resume")
    assert done["status"] == "complete" and "nothing left to do" in done["message"]
    assert [(r["series"], r["run"]) for r in done["runs"]] == [(1, 1), (1, 2)]
    assert done["runs"][1]["stiffness_n_per_m"] == again.curves[1].stiffness_n_per_m.tolist()
    text = labctl_here(capsys, "run", str(proto), "--out", str(out), "--resume").stdout
    assert "nothing left to do" in text and "repetition 1" in text and "repetition 2" in text


def test_bad_inputs_leave_no_campaign_file(tmp_path, capsys):
    proto, out = _protocol(tmp_path), tmp_path / "c.h5"
    assert_one_line_error(labctl_here(capsys, "run", str(proto), "--out", str(out), "--world",
                                      str(tmp_path / "nowhere.toml")), "nowhere.toml")
    assert not out.exists()
    devices = tmp_path / "devices.toml"
    devices.write_text("this is = = not toml\n")
    assert_one_line_error(labctl_here(capsys, "run", str(proto), "--out", str(out), "--backend", "hw",
                                      "--devices", str(devices)), "devices.toml")
    assert not out.exists()


def test_demo_refuses_to_overwrite_a_campaign_without_force(tmp_path, capsys):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "campaign.h5").write_bytes(b"earlier results")
    assert_one_line_error(labctl_here(capsys, "demo", "--out", str(tmp_path / "d")), "campaign.h5", "--force")
    assert (tmp_path / "d" / "campaign.h5").read_bytes() == b"earlier results"
