"""TUI pieces without a screen: the state folded from events, plot data reduction, reference curves, the
operator's hand-over between threads, and ``labctl tui`` argument errors (one line, exit 2)."""

from __future__ import annotations

import math
import subprocess
import threading

import numpy as np
import pytest

from labctl import events as ev
from labctl.cli import main
from labctl.engine import StopRequested
from labctl.physics import roller
from labctl.protocol import load_protocol
from labctl.tui import plotdata as pd
from labctl.tui.operator import TuiOperator
from labctl.tui.state import CampaignState, clock, reason_text
from tests.cli_util import assert_one_line_error, labctl, shipped_environment
from tests.engine_util import impact_event, step_event

pytestmark = pytest.mark.waits  # on subprocesses and frame rates measured over real time (tests/conftest.py)


def step_processed(step: int, load: float, bounce: float, k: float) -> ev.StepProcessed:
    f = np.linspace(0, 2000, 11)
    return step_event(ev.Position(1, 1, step), load, bounce, (bounce * 0.8, bounce * 0.81), k, f, np.ones((1, 11)),
                      np.ones((1, 11)), ("A1Z",), coherence_at_bounce=0.999)


def test_state_header_follows_the_events():
    s = CampaignState()
    assert s.progress_text() == "run -/1 · step -/- · hit -/1"
    s.apply(ev.CampaignStarted(0.0, "quick_check", "qc.h5", "sim", 1, 3, (3,), 2), now=100.0)
    s.apply(ev.RunStarted(0.1, ev.Position(1, 2), "roller type 1"), now=100.1)
    s.apply(ev.StepStarted(0.2, ev.Position(1, 2, 1), 3, 0.0, 38.0), now=100.2)
    s.apply(ev.LoadMeasured(0.3, ev.Position(1, 2, 1), 37.9, True), now=100.3)
    s.apply(ev.Progress(0.4, ev.Position(1, 2, 1, 2), 8, 18, 65.0), now=110.0)
    assert s.header_text(now=115.0) == ("run 2/3 · step 1/3 · hit 2/2 · load 37.9 N · elapsed 00:15 · ETA 01:00"
                                        " · ARMED: waiting for the blow")
    s.apply(step_processed(1, 37.9, 532.48, 2.26e7), now=111.0)
    s.apply(step_processed(2, 116.1, 638.97, 3.33e7), now=112.0)
    assert s.curves[(1, 1)] == ((37.9, 116.1), (2.26e7, 3.33e7))
    assert "bounce 638.97 Hz" in s.modes_text() and "k 33.30 N/µm" in s.modes_text()
    s.apply(ev.Paused(1.0, ev.Position(1, 2, 2, 1)), now=113.0)
    assert s.status == "paused" and s.running
    s.apply(ev.CampaignFinished(2.0, "interrupted", "qc.h5", "stopped"), now=120.0)
    assert s.status == "interrupted" and not s.running
    assert s.elapsed_s(now=500.0) == pytest.approx(20.0)  # the clock stops at the end


def test_clock_and_reason_text():
    assert clock(None) == "--:--" and clock(math.nan) == "--:--"
    assert clock(59.6) == "01:00" and clock(3725) == "1:02:05"
    assert reason_text(("double_hit", "clipped:A2Z")) == "double hit, A2Z clipped"


def test_envelope_keeps_every_extreme_of_a_long_trace():
    rng = np.random.default_rng(3)
    y = rng.normal(size=65536)
    y[40000] = 25.0  # a spike a decimation by striding would miss
    x = np.arange(y.size) / 20480.0
    xs, ys = pd.envelope(x, y, bins=200)
    assert ys.size == 400 and ys.max() == 25.0 and ys.min() == y.min()
    assert xs[np.argmax(ys)] == pytest.approx(40000 / 20480.0)
    assert np.all(np.diff(xs) >= 0)


@pytest.mark.parametrize("n", [401, 1000, 4097, 12345])
def test_the_reduced_traces_are_each_bins_own_extremes(n):
    """Per bin, written out one bin at a time: the envelope's minimum and maximum in sample order, the peak
    reduction's largest finite value (the first of equals; NaN ignored; a bin with none keeps its first sample)."""
    rng = np.random.default_rng(n)
    y = np.round(rng.normal(size=n), 1)  # ties
    y[rng.integers(0, n, n // 8)] = np.nan
    y[: n // 5] = np.nan
    y[n // 2] = np.inf
    x = np.arange(n) * 0.5
    for bins in (200, 150):
        edges = np.linspace(0, n, bins + 1).astype(int)
        want_env, want_peak = [], []
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            seg = y[a:b]
            want_env += sorted((a + int(np.argmin(seg)), a + int(np.argmax(seg))))
            want_peak.append(a + int(np.nanargmax(seg)) if np.isfinite(seg).any() else a)
        xs, ys = pd.envelope(x, y, bins=bins)
        np.testing.assert_array_equal(xs, x[want_env])
        np.testing.assert_array_equal(ys, y[want_env])
        xs, ys = pd.bin_peaks(x, y, bins=bins)
        np.testing.assert_array_equal(xs, x[want_peak])
        np.testing.assert_array_equal(ys, y[want_peak])


def test_frf_band_keeps_the_resonance_at_its_frequency():
    f = np.linspace(0, 2500, 8001)
    zeta, fn = 0.018, 638.97
    mag = 1 / np.abs(fn**2 - f**2 + 2j * zeta * fn * f)
    xs, ys = pd.frf_band(f, mag, pd.frf_limit_hz(fn), bins=150)
    assert xs.max() <= 1.6 * fn and ys.size == 150
    assert xs[np.argmax(ys)] == pytest.approx(f[np.argmax(mag)])


def test_pulse_window_is_centred_on_the_peak():
    fs = 20480.0
    force = np.zeros(4096)
    force[1000:1008] = np.sin(np.linspace(0, np.pi, 8)) * 250
    t, v = pd.pulse_window(force, fs)
    assert t[np.argmax(v)] == 0.0 and v.max() == force.max()
    assert t[0] == pytest.approx(-1.0, abs=0.05) and t[-1] == pytest.approx(3.0, abs=0.05)


def test_model_curves_are_the_papers_fit_and_tripp():
    spec = load_protocol("quick_check").specimens[0]
    curves = pd.model_curves(spec.case(), spec.kind, 10.0, 200.0, points=5)
    assert set(curves) == {"Tripp", "Eq. 5 (Ra 0.2 µm)"}
    load, k = curves["Eq. 5 (Ra 0.2 µm)"]
    length = roller(1).contact_length_m
    expected = 5.151e9 * np.log(load / length / 1.800e3) * length  # Eq. 5, written out independently
    assert k == pytest.approx(expected, rel=1e-9)
    load_t, k_t = curves["Tripp"]
    assert np.all(np.diff(k_t) > 0) and load_t[0] == pytest.approx(10.0)


def test_operator_blocks_the_engine_thread_until_answered_and_can_be_withdrawn():
    shown = []
    op = TuiOperator(lambda fn, *a: fn(*a), shown.append, lambda text: None)
    answers: list[object] = []

    def engine() -> None:
        try:
            answers.append(op.prompt("load drifted", ("continue", "abort"), "confirm"))
            answers.append(op.prompt("rotate", ("ok",), "rotate_rollers"))
        except StopRequested as stop:
            answers.append(stop.status)

    t = threading.Thread(target=engine)
    t.start()
    while not shown:
        threading.Event().wait(0.01)
    assert t.is_alive() and op.pending is shown[0]
    with pytest.raises(ValueError, match="not one of"):
        shown[0].reply("maybe")
    shown[0].reply("abort")
    while len(shown) < 2:
        threading.Event().wait(0.01)
    op.stop("interrupted")  # the technician quits while the second prompt is open
    t.join(5)
    assert answers == ["abort", "interrupted"] and not t.is_alive()
    with pytest.raises(StopRequested):
        op.prompt("again?")


def test_a_pause_asked_during_the_arm_grace_ends_it_and_the_grace_runs_out_by_itself_otherwise():
    """After a person's verdict the engine waits ``arm_grace_s`` before arming the next blow, so a `p` pressed
    just after `y` still holds it; once a pause is asked for the wait has done its job and ends at once."""
    from drivers.interfaces import ImpactReview

    paused = threading.Event()
    shown: list = []
    op = TuiOperator(lambda fn, *a: fn(*a), shown.append, lambda text: None, reviews_hits=True, arm_grace_s=60.0,
                     held=paused.is_set)
    verdicts: list[object] = []
    engine = threading.Thread(target=lambda: verdicts.append(
        op.review_impact(ImpactReview(1, 1, 1, 1, True, (), 200.0, 3e-4))))
    engine.start()
    while not shown:
        threading.Event().wait(0.01)
    shown[0].reply("accept")
    engine.join(0.3)
    assert engine.is_alive() and not verdicts  # the grace: nothing armed yet
    paused.set()  # the technician presses p (the app pauses the run control, then wakes the operator)
    op.wake()
    engine.join(10)  # the old 60 s sleep would still be running
    assert not engine.is_alive() and verdicts == [("accept", "confirmed by the operator: passed the checks")]

    short = TuiOperator(lambda fn, *a: fn(*a), lambda r: r.reply("reject"), lambda text: None, reviews_hits=True,
                        arm_grace_s=0.05)
    assert short.review_impact(ImpactReview(1, 1, 1, 2, True, (), 200.0, 3e-4))[0] == "reject"


def in_process(capsys, *args: str) -> subprocess.CompletedProcess[str]:
    """``labctl`` called in this interpreter (fast), seen as a finished process."""
    capsys.readouterr()
    code = main(list(args))
    out = capsys.readouterr()
    return subprocess.CompletedProcess(args, code, out.out, out.err)


def test_cli_refuses_bad_arguments_with_one_line(tmp_path, capsys):
    assert_one_line_error(in_process(capsys, "tui", str(tmp_path / "nope.toml")), "nope.toml", "not found")
    existing = tmp_path / "old.h5"
    existing.write_bytes(b"x")
    assert_one_line_error(in_process(capsys, "tui", "quick_check", "--out", str(existing)), "already exists",
                          "--resume")
    assert_one_line_error(in_process(capsys, "tui", "quick_check", "--resume"), "--resume needs")
    assert_one_line_error(in_process(capsys, "tui", "quick_check", "--backend", "hw", "--auto-confirm", "2"),
                          "--auto-confirm")
    assert_one_line_error(in_process(capsys, "tui", "--open", str(existing)), "old.h5")


def test_cli_without_a_terminal_says_so(tmp_path):
    """CI and pipes have no terminal: one line pointing to ``labctl run`` instead of a hung screen."""
    proc = labctl("tui", "quick_check", "--out", str(tmp_path / "n.h5"))
    assert_one_line_error(proc, "terminal", "labctl run")
    assert not (tmp_path / "n.h5").exists()


@pytest.mark.parametrize(("lo", "hi", "ticks", "labels"), [
    (0.0, 2000.0, [0, 500, 1000, 1500, 2000], ["0", "500", "1000", "1500", "2000"]),
    (21.7, 130.2, [50, 100], ["50", "100"]),
    (0.0, 1.0, [0.0, 0.2, 0.4, 0.6, 0.8, 1.0], ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]),
    (0.48, 1.0, [0.6, 0.8, 1.0], ["0.6", "0.8", "1.0"]),
])
def test_ticks_fall_on_a_1_2_5_grid(lo, hi, ticks, labels):
    got, text = pd.nice_ticks(lo, hi)
    assert got == pytest.approx(ticks) and text == labels
    step = got[1] - got[0]
    mantissa = step / 10 ** math.floor(math.log10(step))
    assert min(abs(mantissa - m) for m in (1, 2, 5)) < 1e-9
    assert pd.nice_range(1.1857, 44.3) == (0.0, 50.0)


def test_frf_plots_keep_a_fixed_span_and_coherence_on_0_to_1():
    from labctl.tui.plots import FrfPlots, TracePlot

    mag, coh = TracePlot("", "f [Hz]", "|H1|"), TracePlot("", "f [Hz]", "coherence")
    plots = FrfPlots(mag, coh)
    f = np.linspace(0, 10240, 4097)
    for bounce in (500.0, 1200.0):  # the span does not follow the bounce frequency
        h = 1 / np.abs(1 - (f / bounce) ** 2 + 0.05j)
        plots.show(f, h[None], (0.48 + 0.5 * (f < 3000))[None], ("A1Z",), bounce, (bounce * 0.8,), "")
        x = mag.lines["A1Z"][0]
        assert max(x) <= pd.FRF_SPAN_HZ and max(x) > 0.95 * pd.FRF_SPAN_HZ
        assert mag.x_range == coh.x_range == (0.0, pd.FRF_SPAN_HZ) and coh.y_range == (0.0, 1.0)
    assert mag.ylabel == "|H1| [(m/s²)/N]"


def test_repetitions_differ_in_marker_and_colour():
    from labctl.tui.plots import RUN_COLORS, RUN_MARKERS

    assert len(set(RUN_MARKERS)) == len(RUN_MARKERS) and len(set(RUN_COLORS[:3])) == 3


def test_step_blows_average_the_accepted_blows_and_the_one_under_review():
    """The gate's FRF: the operator's verdicts count over the checks', a new step starts afresh."""
    from drivers.interfaces import ImpactReview
    from labctl.processing.frf import blow_spectra, estimate_frf
    from labctl.tui.stepfrf import StepBlows
    from tests.synth_impacts import SynthMode, synth_impacts

    s = synth_impacts([SynthMode("bounce", 745.0, 0.02, np.array([0.04, -0.01]))], ("A1Z", "A4Z"), n_impacts=4,
                      n_samples=8192, snr_db=30.0, seed=3)
    blows = StepBlows()
    blows(ev.StepStarted(0.0, ev.Position(1, 1, 2), 3, 360.0, 40.0))
    for i, accepted in enumerate((True, False, True, True)):  # the checks flag blow 2
        blows(impact_event(ev.Position(1, 1, 2, 1), i + 1, (), s.force_n[i], s.accel_m_per_s2[i], ("A1Z", "A4Z"),
                           accepted=accepted, fs_hz=s.fs_hz))

    def review(attempt: int, step: int = 2) -> ImpactReview:
        return ImpactReview(1, 1, step, attempt, True, (), 200.0, 3e-4)

    frf = blows.frf_so_far(review(4), {3: False})  # the technician rejected blow 3: blows 1 and 4 remain
    assert frf is not None and frf.attempts == (1, 4) and frf.band_coherence_before is None
    expected = estimate_frf(blow_spectra(s.force_n[[0, 3]], s.accel_m_per_s2[[0, 3]], s.fs_hz), [0, 1])
    assert np.allclose(frf.h1_magnitude, np.abs(expected.h1)) and "2 blows averaged" in frf.title()
    both = blows.frf_so_far(review(4), {2: True})  # the flagged blow accepted by the technician
    assert both.attempts == (1, 2, 3, 4) and 0 < both.band_coherence_before <= 1 and "→" in both.title()
    assert blows.frf_so_far(review(5), {}) is None and blows.frf_so_far(review(1, step=3), {}) is None
    blows(ev.StepStarted(2.0, ev.Position(1, 1, 3), 3, 720.0, 80.0))
    assert blows.frf_so_far(review(4), {}) is None


@pytest.mark.parametrize(("env", "period_s"), [(None, 1 / 20), ("60", 1 / 60)])
def test_the_screen_redraws_at_most_twenty_times_a_second_unless_textual_fps_says(env, period_s):
    """The acquisition PC draws the screen too: 20 frames a second by default, TEXTUAL_FPS still overrides."""
    import sys

    environ = shipped_environment(**({} if env is None else {"TEXTUAL_FPS": env}))
    code = "import labctl.tui, textual.screen as s; print(repr(s.UPDATE_PERIOD))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=environ, check=True)
    assert float(out.stdout) == pytest.approx(period_s)
