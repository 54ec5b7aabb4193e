"""The digital twin: one shared state of the simulated rig that every simulated instrument acts on.

Knob angle → spring compression → load per roller (from the preload, never below it) → each seated roller's
stiffness from the hidden world → rig modes → the response to each blow. Rig time is virtual: nothing sleeps.
Test hooks (double hit, overload, dead channel, creep, unplugged device) are methods here, not in the
instrument interfaces; the world's faults (``drivers.sim.faults``) are drawn here from their own random stream
and logged in ``fault_log``. A blow's record shows the contact's first-order nonlinearity (``blow_modes``).
Separate random streams for seating, blows, noise, the load cell and faults keep one stream's use (e.g. extra
load-cell reads) from changing another's data: everything is reproducible from the seed.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivers.interfaces import Record, TriggerSpec
from drivers.sim.faults import FaultSettings, mains_hum
from drivers.sim.model import (
    ModesFunction,
    ModesLike,
    RigLike,
    SeatedRoller,
    SimSettings,
    Specimen,
    SwingStiffnessFunction,
)
from drivers.sim.response import Blow, digitise, modal_model, response
from drivers.sim.springs import SpringStacks

SETTLE_OVERSHOOT = 0.03  # fraction of a load step the load cell overshoots right after a knob turn


@dataclass(frozen=True)
class Strike:
    """A blow as delivered: when (rig time) and where in the sample grid its force crosses the trigger."""

    blow: Blow
    time_s: float
    sample_phase: float
    overload_channel: str | None = None


class RigTwin:
    """State of the simulated rig: knob angle, seated rollers, rig clock, the blows delivered, test hooks."""

    def __init__(
        self,
        rig: RigLike,
        specimen: Specimen,
        modes: ModesFunction,
        *,
        swing_stiffness: SwingStiffnessFunction,
        seed: int | None = None,
        settings: SimSettings | None = None,
        clock_start_s: float | None = None,
        faults: FaultSettings | None = None,
    ) -> None:
        seq = np.random.SeedSequence(seed)
        self.seed: int = int(seq.entropy)  # type: ignore[arg-type]
        self._rng_seat, self._rng_blow, self._rng_noise, self._rng_cell, self._rng_fault = (
            np.random.default_rng(s) for s in seq.spawn(5)
        )
        self.rig, self.specimen, self._modes_fn, self._swing_fn = rig, specimen, modes, swing_stiffness
        self.settings = settings or SimSettings()
        self.faults = faults or FaultSettings()
        self.fault_log: list[tuple[float, str]] = []  # (rig time, what happened): the faults actually generated
        self.slack_deg = 0.0
        self.pulled_channel: str | None = None  # a cable pulled at the last seating (fault): reads flat 0
        self._creep_pending = False  # a loose knob nut: the blows of this step start it creeping
        self.clock_start_s = time.time() if clock_start_s is None else clock_start_s
        self.time_s = 0.0
        self.knob_angle_deg = 0.0
        self.rotations = 0
        self.strikes: list[Strike] = []
        self.dead_channels: set[str] = set()
        self.unplugged: set[str] = set()
        self.creep_n_per_s = self.settings.load_creep_n_per_s
        self._creep_n = 0.0
        self._creep_since_s = 0.0
        self._reads_since_turn = self.settings.load_cell_settle_reads
        self._overshoot_n = 0.0
        self._tare_n = 0.0
        self._next_double: tuple[float, float] | None = None
        self._next_overload: str | None = None
        self._next_peak_n: float | None = None
        self._modes_cache: tuple[tuple[float, ...], ModesLike] | None = None
        self.rollers: list[SeatedRoller] = self._seat()
        lo = rig.loading
        self.springs: SpringStacks | None = (  # None: the rig file's linear nominal springs
            SpringStacks(lo.rods, lo.spring_rate_n_per_m, lo.thread_pitch_m, rig.roller_count,
                         seed=self.settings.spring_stack_seed,
                         scale=self.settings.spring_imperfection) if self.settings.spring_imperfection > 0 else None)

    # --- loading -------------------------------------------------------------------------------------
    @property
    def preload_n(self) -> float:
        return float(self.rig.preload_per_roller_n)

    def load_per_roller_n(self) -> float:
        """Load on each roller now: preload + spring force (the nut takes up slack first) + creep since the turn."""
        if self.springs is not None:
            spring = self.springs.load_per_roller_n()
        else:
            spring = max(0.0, self.knob_angle_deg - self.slack_deg) * self.rig.load_per_knob_degree_n
        creep = self._creep_n + self.creep_n_per_s * (self.time_s - self._creep_since_s)
        return max(self.preload_n, self.preload_n + spring + creep)

    def turn_knobs(self, angle_deg: float) -> None:
        """Turn all knobs together (positive tightens); the load cell then needs a few reads to settle."""
        if not math.isfinite(angle_deg):
            raise ValueError(f"knob angle must be a finite number of degrees, got {angle_deg!r}")
        before = self.load_per_roller_n()
        self.knob_angle_deg += angle_deg
        if self.springs is not None:
            self.springs.move_to(self.knob_angle_deg - self.slack_deg)
        self.time_s += abs(angle_deg) * self.settings.knob_turn_s_per_deg
        self._creep_n, self._creep_since_s = 0.0, self.time_s
        if self.faults.creep_rate and angle_deg > 0:
            self.creep_n_per_s = self.settings.load_creep_n_per_s
            self._creep_pending = bool(self._rng_fault.random() < self.faults.creep_rate)
        self._overshoot_n = SETTLE_OVERSHOOT * self.rig.roller_count * (self.load_per_roller_n() - before)
        self._reads_since_turn = 0

    def set_load_per_roller(self, load_n: float) -> None:
        """Put the rig directly at a load per roller (sets the equivalent knob angle, already settled)."""
        if not (math.isfinite(load_n) and load_n >= self.preload_n):
            raise ValueError(
                f"load {load_n!r} N per roller is below the preload {self.preload_n:.1f} N (the upper disc's weight)"
            )
        if self.springs is not None:
            self.knob_angle_deg = self.slack_deg + self.springs.angle_for_load(load_n - self.preload_n)
            self.springs.reset_to(self.knob_angle_deg - self.slack_deg)
        else:
            self.knob_angle_deg = self.slack_deg + (load_n - self.preload_n) / self.rig.load_per_knob_degree_n
        self._creep_n, self._creep_since_s = 0.0, self.time_s
        self._overshoot_n = 0.0
        self._reads_since_turn = self.settings.load_cell_settle_reads

    def read_load_cell(self) -> tuple[float, bool]:
        """Total force on the three rollers as the load cell shows it (noise, settling, tare), and stability."""
        s = self.settings
        self.time_s += s.load_cell_read_s
        settled = self._reads_since_turn >= s.load_cell_settle_reads
        transient = 0.0 if settled else self._overshoot_n * 0.5**self._reads_since_turn
        self._reads_since_turn += 1
        rollers = self.rig.roller_count
        value = rollers * self.load_per_roller_n() + transient + self._rng_cell.normal(0.0, s.load_cell_noise_n)
        drifting = abs(rollers * self.creep_n_per_s) > s.stable_rate_n_per_s
        return float(value - self._tare_n), settled and not drifting

    def load_cell_fault(self) -> str | None:
        """Whether this read fails on the line: ``"timeout"`` (no answer), ``"garbled"`` (unreadable reply) or None."""
        f = self.faults
        if not (f.load_cell_timeout_rate or f.load_cell_garbled_rate):
            return None
        u = self._rng_fault.random()
        kind = ("timeout" if u < f.load_cell_timeout_rate
                else "garbled" if u < f.load_cell_timeout_rate + f.load_cell_garbled_rate else None)
        if kind is not None:
            self.time_s += self.settings.load_cell_read_s
            self._log(f"load cell read {kind}")
        return kind

    def _log(self, what: str) -> None:
        self.fault_log.append((self.time_s, what))

    def tare(self) -> None:
        """Zero the load cell at the force it carries now."""
        self._tare_n = 0.0
        self._tare_n = self.read_load_cell()[0]

    # --- rollers and dynamics ------------------------------------------------------------------------
    def _seat(self) -> list[SeatedRoller]:
        rollers = [self.specimen.seat(self._rng_seat) for _ in range(self.rig.roller_count)]
        f = self.faults
        if f.unequal_seating_rate and self._rng_fault.random() < f.unequal_seating_rate:
            worse = int(self._rng_fault.integers(len(rollers)))
            rollers[worse] = self.specimen.on_burr(rollers[worse], f.unequal_seating_gap_m)
            self._log(f"roller {worse + 1} seated on a {f.unequal_seating_gap_m * 1e6:g} µm burr")
        self.pulled_channel = None
        if f.dead_channel_rate and self._rng_fault.random() < f.dead_channel_rate:
            self.pulled_channel = str(self._rng_fault.choice(self.rig.channels))
            self._log(f"{self.pulled_channel} cable pulled: the channel reads 0 until the next seating")
        return rollers

    def rotate_rollers(self) -> None:
        """The disc was lifted and the rollers turned ~±5°: each roller now touches on a new contact spot, and the
        knob nuts, run back on, take up a new amount of slack before the springs bite."""
        self.rollers = self._seat()
        self.rotations += 1
        if self.settings.knob_slack_deg > 0:
            self.slack_deg = float(self._rng_seat.uniform(0.0, self.settings.knob_slack_deg))

    def roller_stiffness_n_per_m(self) -> list[float]:
        load = self.load_per_roller_n()
        return [float(r.stiffness_n_per_m(load)) for r in self.rollers]

    def modes(self) -> ModesLike:
        ks = tuple(self.roller_stiffness_n_per_m())
        if self._modes_cache is None or self._modes_cache[0] != ks:
            self._modes_cache = (ks, self._modes_fn(self.rig, list(ks)))
        return self._modes_cache[1]

    def truth(self) -> dict[str, Any]:
        """What the rig really is right now: load, each roller's stiffness, bounce and tilt frequencies."""
        modes = self.modes()
        return {
            "load_n": self.load_per_roller_n(),
            "roller_stiffness_n_per_m": self.roller_stiffness_n_per_m(),
            "bounce_hz": float(modes.bounce_hz),
            "tilt_hz": [float(f) for f in modes.tilt_hz],
        }

    # --- blows and records ---------------------------------------------------------------------------
    def strike(self) -> Strike:
        """Deliver one blow: force and width vary hit to hit, the impact point scatters around the nominal."""
        s, rng = self.settings, self._rng_blow
        width = rng.uniform(s.pulse_width_min_s, s.pulse_width_max_s)
        peak = self.hammer_level_n() * math.exp(s.peak_force_rel * rng.standard_normal())
        dx, dy = rng.normal(0.0, s.impact_scatter_m, 2) if s.impact_scatter_m > 0 else (0.0, 0.0)
        phase = rng.uniform(0.0, 1.0)
        if self._next_peak_n is not None:
            peak, self._next_peak_n = self._next_peak_n, None
        if self._creep_pending:
            self._creep_pending = False
            self.set_creep(self.faults.creep_n_per_s)
            self._log(f"load creeps {self.faults.creep_n_per_s:g} N/s per roller from this blow on (loose knob nut)")
        delay, ratio = self._next_double or self._random_double()
        if self._next_overload is None:
            self._next_overload = self._random_overload()
        x, y = self.rig.hammer_xy_m
        blow = Blow(peak, width, x + float(dx), y + float(dy), delay, ratio)
        strike = Strike(blow, self.time_s, phase, self._next_overload)
        self._next_double = self._next_overload = None
        self.strikes.append(strike)
        return strike

    def hammer_level_n(self) -> float:
        """The mean peak force the technician aims at now: a light blow at a light load (the paper's practice),
        ``peak_force_per_load`` × the load per roller within the hammer's usable range, else ``peak_force_n``."""
        s = self.settings
        if s.peak_force_per_load <= 0:
            return s.peak_force_n
        return min(s.peak_force_n, max(s.peak_force_min_n, s.peak_force_per_load * self.load_per_roller_n()))

    def _random_double(self) -> tuple[float, float]:
        f, rng = self.faults, self._rng_fault
        if not (f.double_hit_rate or f.late_double_hit_rate):
            return 0.0, 0.0
        u = rng.random()
        if u < f.double_hit_rate:
            delay, ratio = rng.uniform(1e-3, 3e-3), rng.uniform(0.2, 0.6)
        elif u < f.double_hit_rate + f.late_double_hit_rate:
            delay, ratio = rng.uniform(2e-3, 10e-3), rng.uniform(0.01, 0.05)
        else:
            return 0.0, 0.0
        self._log(f"double hit: second pulse {ratio:.0%} at +{delay * 1e3:.1f} ms")
        return float(delay), float(ratio)

    def _random_overload(self) -> str | None:
        f, rng = self.faults, self._rng_fault
        if not (f.overload_rate and rng.random() < f.overload_rate):
            return None
        channel = str(rng.choice(("F", *self.rig.channels)))
        self._log(f"overload on {channel}")
        return channel

    def blow_modes(self, blow: Blow) -> ModesLike:
        """The modes the record of this blow shows: the contact is nonlinear, so the force swing ΔF the blow puts
        through each roller (from the bounce mode's response to the blow's impulse) shifts its effective stiffness
        (the ``swing_stiffness`` function the physics passed in)."""
        static = self.modes()
        scale = self.settings.contact_nonlinearity
        if scale == 0.0:
            return static
        impulse = blow.impulse_n_s()
        b = int(np.argmin(np.abs(np.asarray(static.frequencies_hz) - static.bounce_hz)))
        relative = static.vertical_at("upper", 0.0, 0.0, b) - static.vertical_at("lower", 0.0, 0.0, b)
        omega = 2.0 * math.pi * static.bounce_hz
        swing = abs(omega * static.vertical_at("upper", blow.x_m, blow.y_m, b) * impulse / relative)
        swing /= self.rig.roller_count
        load = self.load_per_roller_n()
        swing = min(swing, 0.9 * load)
        ks = [self._swing_fn(r.stiffness_n_per_m, load, swing, scale) for r in self.rollers]
        return self._modes_fn(self.rig, ks)

    def record(self, strike: Strike, sample_rate_hz: float, n_samples: int, trigger: TriggerSpec) -> Record | None:
        """The record the DAQ captures of a blow, or None if its force never reaches the trigger level."""
        s, blow = self.settings, strike.blow
        if blow.peak_n < trigger.level_n:
            return None
        channels = tuple(self.rig.channels)
        t = np.arange(n_samples) / sample_rate_hz
        crossing = (trigger.pretrigger_samples - strike.sample_phase) / sample_rate_hz
        force = blow.force_n(t, blow.onset_s(crossing, trigger.level_n))
        model = modal_model(self.blow_modes(blow), self.rig.flexible_modes, channels, blow.x_m, blow.y_m)
        accel = response(model, force, sample_rate_hz)
        if strike.overload_channel is not None:
            gain = self._overload_gain(strike.overload_channel, force, accel, channels)
            force, accel = force * gain, accel * gain
        flat = np.isin(channels, [c for c in (self._random_dropout(channels), self.pulled_channel) if c])
        accel[np.isin(channels, sorted(self.dead_channels))] = 0.0
        if self.faults.mains_hum_m_per_s2 > 0:
            accel += mains_hum(n_samples, sample_rate_hz, self.faults.mains_hum_m_per_s2, self.faults.mains_hz,
                               self._rng_fault, len(channels))
        force = force + self._noise(s.force_noise_n, force.shape)
        accel += self._noise(s.accel_noise_m_per_s2, accel.shape)
        force, f_clip = digitise(force, s.force_range_n, s.adc_bits)
        accel, a_clip = digitise(accel, s.accel_range_m_per_s2, s.adc_bits)
        accel[flat], a_clip[flat] = 0.0, False  # an open IEPE input: the front end's open-circuit detection reads 0
        self.time_s = max(self.time_s, strike.time_s) + n_samples / sample_rate_hz
        clipped = (("F",) if f_clip[0] else ()) + tuple(np.asarray(channels)[a_clip].tolist())
        return Record(sample_rate_hz, force, accel, channels, trigger.pretrigger_samples,
                      self.clock_start_s + strike.time_s, clipped)

    def _noise(self, rms: float, shape: tuple[int, ...]) -> np.ndarray:
        """Gaussian noise of ``rms`` from the noise stream (the same numbers as ``normal(0, rms, shape)``, scaled in
        place instead of through a second array)."""
        out = self._rng_noise.standard_normal(shape)
        out *= rms
        return out

    def _random_dropout(self, channels: tuple[str, ...]) -> str | None:
        f, rng = self.faults, self._rng_fault
        if not (f.intermittent_channel_rate and rng.random() < f.intermittent_channel_rate):
            return None
        channel = str(rng.choice(channels))
        self._log(f"{channel} dropped out")
        return channel

    def _overload_gain(self, channel: str, force: np.ndarray, accel: np.ndarray, channels: tuple[str, ...]) -> float:
        if channel == "F":
            return 1.2 * self.settings.force_range_n / float(np.max(np.abs(force)))
        peak = float(np.max(np.abs(accel[channels.index(channel)])))
        return 1.2 * self.settings.accel_range_m_per_s2 / peak

    # --- test hooks ----------------------------------------------------------------------------------
    def next_blow_double(self, delay_s: float = 1.5e-3, ratio: float = 0.4) -> None:
        """Make the next blow a double hit: a second pulse ``delay_s`` after the first, ``ratio`` as strong."""
        if not (delay_s > 0 and ratio > 0):
            raise ValueError(f"double hit needs delay_s > 0 and ratio > 0, got {delay_s!r}, {ratio!r}")
        self._next_double = (delay_s, ratio)

    def next_blow_overload(self, channel: str = "F") -> None:
        """Make the next blow hard enough that ``channel`` (``F`` or ``A1X`` … ``A4Z``) exceeds its range."""
        if channel != "F" and channel not in self.rig.channels:
            raise ValueError(f"unknown channel {channel!r}; expected F or one of {', '.join(self.rig.channels)}")
        self._next_overload = channel

    def next_blow_peak(self, peak_n: float) -> None:
        """Fix the next blow's peak force (e.g. below the trigger level: the DAQ then times out)."""
        self._next_peak_n = float(peak_n)

    def kill_channel(self, channel: str) -> None:
        """A broken accelerometer cable: the channel records noise only from now on."""
        if channel not in self.rig.channels:
            raise ValueError(f"unknown channel {channel!r}; expected one of {', '.join(self.rig.channels)}")
        self.dead_channels.add(channel)

    def set_creep(self, n_per_s: float) -> None:
        """Load drift per roller in N per second of rig time since the last knob turn (negative: relaxation)."""
        self._creep_n += self.creep_n_per_s * (self.time_s - self._creep_since_s)
        self._creep_since_s = self.time_s
        self.creep_n_per_s = float(n_per_s)

    def unplug(self, device: str) -> None:
        """The named instrument goes away: its next operation raises DeviceDisconnected."""
        self.unplugged.add(device)

    def replug(self, device: str) -> None:
        self.unplugged.discard(device)
