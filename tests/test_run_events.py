"""What happened at the rig reaches every reader: a load drift answered "continue", a pulled cable (dead channel)
and an operator's override with its reason are stored with the step and shown by ``process --json``, the
report (run events, per-step notes, the verdict) and ``labctl run``'s live output.

One small simulated campaign (one repetition, 2 blows a step) is run once for the module: the springs creep
from the first blow (the drift condition trips after step 1 and the scripted operator continues), A3X's cable
is pulled from the first blow, and the operator rejects the clean first blow of step 1 with a reason.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest

from drivers.operators import ScriptedOperator
from drivers.sim import RigTwin
from labctl import events as ev
from labctl.cli import main
from labctl.cli.progress import ProgressPrinter
from labctl.report.notes import step_events
from labctl.storage import CampaignReader
from tests.engine_util import Recorder, short_protocol

REASON = "hammer slipped off the disc edge"


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str, Recorder]:
    from labctl.campaign import run_campaign

    out = tmp_path_factory.mktemp("events") / "events.h5"
    original = RigTwin.strike
    seen: list[RigTwin] = []

    def strike(self: RigTwin):  # noqa: ANN202
        if not seen:
            seen.append(self)
            self.set_creep(30.0)
            self.pulled_channel = "A3X"  # the cable pulled: the channel reads flat 0
        return original(self)

    mp = pytest.MonkeyPatch()
    mp.setattr(RigTwin, "strike", strike)
    operator = ScriptedOperator(reviews={(1, 1, 1, 1): ("reject", REASON)})

    def retighten(message: str, choices: tuple[str, ...]) -> str:  # the technician sets the knobs again
        seen[0].set_creep(0.0)
        return choices[0]

    operator.on("confirm", retighten)
    events = Recorder()
    live = io.StringIO()
    try:
        outcome = run_campaign(short_protocol(max_load=120.0, samples=8192, impacts=2, reps=1), out=out,
                               backend="sim", seed=3, operator=operator, subscribers=(events, ProgressPrinter(live)))
    finally:
        mp.undo()
    assert outcome.status == "complete", outcome.message
    return out, live.getvalue(), events


def test_the_step_record_holds_drift_channels_and_override(campaign):
    path, _, _ = campaign
    with CampaignReader(path) as reader:
        steps = reader.runs(1)[0].steps
    first = step_events(steps[0])
    assert first.drift_continued and first.load_after_n > first.load_before_n * 1.05  # the springs crept
    assert first.channels_dropped == {"A3X": "dead (no signal in the step's FRF)"}
    assert "A3X" not in first.channels_used and "A3Z" in first.channels_used
    assert [(o.attempt, o.accepted, o.checks, o.reason) for o in first.overrides] == [(1, False, "clean", REASON)]
    notes = " | ".join(first.notes())
    assert "load drifted from" in notes and "the operator continued" in notes
    assert "channel A3X left out" in notes and REASON in notes


def test_process_json_reports_what_happened(campaign, capsys):
    path, _, _ = campaign
    assert main(["process", str(path), "--json"]) == 0
    step1 = json.loads(capsys.readouterr().out)["steps"][0]
    assert step1["load_drifted"] and step1["drift_continued_by_operator"]
    assert step1["load_after_n"] > step1["load_before_n"]
    assert step1["channels_dropped"] == {"A3X": "dead (no signal in the step's FRF)"}
    assert step1["overrides"] == [{"impact": 1, "accepted": False, "checks": "clean", "reason": REASON}]
    assert step1["operator_verdicts"][0] == step1["overrides"][0]  # every operator decision, overrides first here
    assert any("load drifted" in n for n in step1["notes"])


def test_labctl_run_output_says_it_live(campaign):
    _, live, events = campaign
    assert "A3X" in live and "dead" in live  # the pulled cable, not only in the file
    assert "load drifted" in live
    assert REASON in live
    # said when it arose: the drift before the step's result line
    assert live.index("load drifted") < live.index("step 1:")
    assert events.of(ev.Suspended)


def test_the_report_shows_run_events_and_disowns_the_drifted_step(campaign, tmp_path):
    import html as html_lib
    import re

    from labctl.report import build_report

    path, _, _ = campaign
    res = build_report(path, tmp_path / "report")
    page = Path(res.html).read_text(encoding="utf-8")
    text = html_lib.unescape(re.sub(r"<[^>]+>", " ", page))
    assert "Run events" in text and "load drifted from" in text and "the operator continued" in text
    assert "channel A3X left out: dead" in text
    assert REASON in text and "rejected by the operator against the checks" in text
    step1 = next(v for v in res.verdicts if v["step"] == 1)
    assert step1["verdict"] == "cannot tell"  # never a plain pass (nor fail) at a load that did not hold
    assert "load drifted" in next(v.note for v in _verdicts(path) if v.step == 1)
    assert "rails Ra 0.2 µm" in text  # the series is named by specimen and rail
    assert "<thead>" in page and "@media print" in page and "spread" in text and "(largest − smallest)" in text


def _verdicts(path: Path):  # noqa: ANN202
    from labctl.report.data import load_report_data
    from labctl.report.verdict import series_verdicts

    data = load_report_data(path)
    return [v for s in data.series for v in series_verdicts(s, data.rig)]


async def test_the_browser_shows_the_drift_the_dead_channel_and_the_override(campaign):
    from labctl.tui import LabApp, TuiSettings
    from labctl.tui.browser import BrowserScreen
    from tests.test_tui import SIZE, wait_for
    from tests.test_tui_browse import tree_nodes

    path, _, _ = campaign
    app = LabApp(TuiSettings(), open_path=path)
    async with app.run_test(size=SIZE) as pilot:
        screen = await wait_for(pilot, lambda: isinstance(app.screen, BrowserScreen) and app.screen)
        await pilot.pause(0.1)
        tree = screen.query_one("#tree")
        nodes = tree_nodes(tree.root)
        labels = {n.data: str(n.label) for n in nodes if n.data}
        assert "LOAD DRIFTED" in labels[("step", 1, 1, 1)] and "A3X left out" in labels[("step", 1, 1, 1)]
        assert labels[("impact", 1, 1, 1, 1)].endswith("REJECTED by the operator (clean)")
        tree.move_cursor(next(n for n in nodes if n.data == ("step", 1, 1, 1)))
        await pilot.pause(0.2)
        detail = str(screen.query_one("#detail").render())
        assert "load drifted from" in detail and "channel A3X left out: dead" in detail and REASON in detail


def test_the_stiffness_table_flags_the_drifted_step_for_the_discrepancy_workflow(campaign, tmp_path):
    from labctl.stiffness_table import read_stiffness_table, write_stiffness_table
    from labctl.storage import campaign_stiffness_points

    path, _, _ = campaign
    points = campaign_stiffness_points(path)
    first = points[0]
    assert first.drifted and "channels_left_out" in first.flags and "operator_override" in first.flags
    assert first.load_after_n is not None and first.load_after_n > first.load_n * 1.05
    csv = tmp_path / "k.csv"
    write_stiffness_table(csv, points)
    again = read_stiffness_table(csv)  # the optional columns round-trip
    assert [p.flags for p in again] == [p.flags for p in points]
    assert again[0].load_after_n == pytest.approx(first.load_after_n)
