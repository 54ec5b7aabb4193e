"""The operator's verdicts are what gets processed: live, in the stored step results and in ``labctl process``.

The twin does not double-hit by itself; the test makes the campaign's first blow a double hit through the
twin's own test hook (``RigTwin.next_blow_double``), called from a wrapper around ``RigTwin.strike``.
"""

from __future__ import annotations

import pytest

from labctl.campaign import load_operator_script
from labctl.errors import InputError
from labctl.storage import CampaignReader
from tests.cli_util import assert_one_line_error, labctl_here, labctl_here_json

SCRIPT = """
[[review]]
step = 1
attempt = 1
verdict = "accept"
reason = "second pulse judged harmless"

[[review]]
series = 1
run = 1
step = 2
attempt = 1
verdict = "reject"
reason = "hammer slipped on the disc edge"
"""


def test_scripted_verdicts_are_honoured_live_stored_and_reprocessed(tmp_path, capsys, first_blow_double):
    script = tmp_path / "operator.toml"
    script.write_text(SCRIPT)
    out = tmp_path / "a.h5"
    ran = labctl_here_json(capsys, "run", "protocols/quick_check.toml", "--backend", "sim", "--seed", "2",
                           "--out", str(out), "--operator", str(script))
    assert ran["status"] == "complete"
    with CampaignReader(out) as r:
        steps = r.runs(1)[0].steps
        first = steps[0].impacts[0]
        assert "double_hit" in first.checks.reasons and not first.checks.accepted  # the checks flagged it
        assert first.verdict.accepted and first.verdict.source == "operator"
        assert first.verdict.reason == "second pulse judged harmless"
        clean = steps[1].impacts[0]
        assert clean.checks.accepted and not clean.verdict.accepted and clean.verdict.source == "operator"
        stored = {s.step: s.result.used_attempts for s in steps}
        unused = [len(s.impacts) - len(s.result.used_attempts) for s in steps]
        verdicts = {s.step: {i.attempt: i.accepted for i in s.impacts} for s in steps}
    # step 1 uses the flagged blow the operator accepted; step 2 never uses the clean blow they rejected
    assert stored[1][0] == 1 and 1 not in stored[2] and all(len(u) == 2 for u in stored.values())
    assert all(verdicts[step][a] for step, used in stored.items() for a in used)  # only accepted blows are used
    processed = labctl_here_json(capsys, "process", str(out))
    assert {s["step"]: tuple(s["used_impacts"]) for s in processed["steps"]} == stored
    assert [s["rejected_impacts"] for s in processed["steps"]] == unused and unused[1] >= 1


def test_a_bad_operator_script_is_refused_before_anything_is_written(tmp_path, capsys):
    script = tmp_path / "operator.toml"
    script.write_text('[[review]]\nstep = 1\nattempt = 1\nverdict = "maybe"\nreason = "x"\n')
    out = tmp_path / "a.h5"
    proc = labctl_here(capsys, "run", "protocols/quick_check.toml", "--out", str(out), "--operator", str(script))
    assert_one_line_error(proc, "operator.toml", "verdict = 'maybe'", "accept, reject")
    assert not out.exists()


@pytest.mark.parametrize(("text", "fragment"), [
    ('[[review]]\nstep = 1\nverdict = "accept"\nreason = "ok"\n', "attempt is missing"),
    ('[[review]]\nstep = 0\nattempt = 1\nverdict = "accept"\nreason = "ok"\n', "step = 0"),
    ('[[review]]\nstep = 1\nattempt = 1\nverdict = "reject"\nreason = ""\n', "reason = ''"),
    ('[[review]]\nstep = 1\nattempt = 1\nverdict = "reject"\nreason = "a"\nwhy = 1\n', "unknown key 'why'"),
    ('[reviews]\n', "unknown table 'reviews'"),
    ('[[review]]\nstep = 1\nattempt = 1\nverdict = "reject"\nreason = "a"\n'
     '[[review]]\nstep = 1\nattempt = 1\nverdict = "accept"\nreason = "b"\n', "has a verdict already"),
])
def test_operator_script_errors_name_the_entry_and_the_key(tmp_path, text, fragment):
    script = tmp_path / "op.toml"
    script.write_text(text)
    with pytest.raises(InputError, match="op.toml") as err:
        load_operator_script(script)
    assert fragment in str(err.value)


def test_a_reviewing_console_operator_is_asked_after_every_blow(tmp_path):
    import io

    from drivers.operators import ConsoleOperator
    from labctl.campaign import run_campaign
    from tests.engine_util import short_protocol

    answers = io.StringIO("\n" + "reject\n" + "\n" * 40)  # mount; the first blow rejected; then Enter = accept
    shown = io.StringIO()
    operator = ConsoleOperator(answers, shown, reviews_impacts=True)
    outcome = run_campaign(short_protocol(reps=1, samples=8192), out=tmp_path / "c.h5", seed=3, operator=operator)
    assert outcome.status == "complete"
    with CampaignReader(tmp_path / "c.h5") as r:
        steps = r.runs(1)[0].steps
        first = steps[0].impacts[0]
        assert not first.accepted and first.verdict.source == "operator"
        assert steps[0].result.used_attempts == (2, 3)
        assert all(i.verdict.source == "operator" for s in steps for i in s.impacts)  # every blow was put to them
    assert shown.getvalue().count("accept or reject?") == sum(len(s.impacts) for s in steps)
