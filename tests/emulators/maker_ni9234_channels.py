"""The NI 9234 emulator's task objects below the task: channels, timing and triggers, with the real package's
names and parameters (facts: tests/emulators/MAKER_FACTS.md)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from tests.emulators.maker_ni9234_api import (
    AccelSensitivityUnits,
    AccelUnits,
    AcquisitionType,
    Coupling,
    DaqError,
    Edge,
    ExcitationSource,
    Slope,
    TerminalConfiguration,
    TriggerType,
    VoltageUnits,
)
from tests.emulators.maker_ni9234_chassis import (
    _ACTIVE,
    G_M_PER_S2,
    IEPE_CURRENT_A,
    INPUT_RANGE_V,
    VALID_RATES_HZ,
    Input,
    _expand,
    coerce_rate,
)

if TYPE_CHECKING:
    from tests.emulators.maker_ni9234 import Task

# -- task objects ----------------------------------------------------------------------------------------------------
class _Chan:
    def __init__(self, physical: str, name: str, source: Input, kind: str, **cfg: object) -> None:
        self.physical, self.name, self.source, self.kind = physical, name, source, kind
        self.min_val = float(cfg["min_val"])
        self.max_val = float(cfg["max_val"])
        self.units = cfg.get("units")
        self.sensitivity_v_per_unit = 1.0
        if kind == "accel":
            sens = float(cfg["sensitivity"])
            sens_v_per_g = sens * 1e-3 if cfg["sensitivity_units"] == AccelSensitivityUnits.MILLIVOLTS_PER_G else sens
            per_unit = sens_v_per_g / G_M_PER_S2 if self.units == AccelUnits.METERS_PER_SECOND_SQUARED else sens_v_per_g
            self.sensitivity_v_per_unit = per_unit
            self.ai_excit_src = cfg["current_excit_source"]
            self.ai_excit_val = float(cfg["current_excit_val"])
            self.ai_coupling = Coupling.AC
        else:
            self.ai_excit_src, self.ai_excit_val, self.ai_coupling = ExcitationSource.NONE, 0.0, Coupling.DC

    def excitation_on(self) -> bool:
        return self.ai_excit_src == ExcitationSource.INTERNAL and self.ai_excit_val > 0

    def verify(self, task: str) -> None:
        def bad(prop: str, value: object, possible: str) -> DaqError:
            return DaqError(f"Requested value is not a supported value for this property. The property value may be "
                            f"invalid because it conflicts with another property.\nProperty: {prop}\nRequested Value: "
                            f"{value}\nPossible Values: {possible}\nChannel Name: {self.name}", -200077, task)
        if self.ai_excit_src == ExcitationSource.INTERNAL and not math.isclose(self.ai_excit_val, IEPE_CURRENT_A):
            raise bad("AI.Excit.Val", self.ai_excit_val, "2.0e-3")
        if self.ai_excit_src == ExcitationSource.EXTERNAL:
            raise bad("AI.Excit.Src", "External", "Internal, None")
        if self.excitation_on() and self.ai_coupling != Coupling.AC:
            raise bad("AI.Coupling", self.ai_coupling.name, "AC")  # IEPE current only in AC-coupled mode
        if self.ai_coupling == Coupling.GND:
            raise bad("AI.Coupling", "GND", "AC, DC")
        for prop, v in (("AI.Max", self.max_val), ("AI.Min", self.min_val)):
            if abs(v * self.sensitivity_v_per_unit) > INPUT_RANGE_V * (1 + 1e-9):
                raise bad(prop, v, f"{-INPUT_RANGE_V / self.sensitivity_v_per_unit} to "
                          f"{INPUT_RANGE_V / self.sensitivity_v_per_unit}")

    def input_volts(self, t: float) -> float:
        """Voltage at the BNC: an unpowered IEPE sensor is silent; a powered one rides on its DC bias."""
        src = self.source
        if src.iepe_sensor and not self.excitation_on():
            return 0.0
        return src.volts(t) + (src.iepe_bias_v if src.iepe_sensor else 0.0)

    def scaled(self, volts: float) -> float:
        return max(-INPUT_RANGE_V, min(INPUT_RANGE_V, volts)) / self.sensitivity_v_per_unit


class AIChannel:
    """The object ``add_ai_*_chan`` returns; property writes apply to every channel it names."""

    def __init__(self, chans: list[_Chan]) -> None:
        object.__setattr__(self, "_chans", chans)

    def __getattr__(self, name: str) -> object:
        return getattr(self._chans[0], name)

    def __setattr__(self, name: str, value: object) -> None:
        for c in self._chans:
            setattr(c, name, value)


class AIChannelCollection:
    def __init__(self, task: Task) -> None:
        self._task = task

    def __getitem__(self, index: int) -> AIChannel:
        return AIChannel([self._task._chans[index]])

    def __len__(self) -> int:
        return len(self._task._chans)

    def _add(self, physical_channel: str, name: str, kind: str, **cfg: object) -> AIChannel:
        chassis = _ACTIVE[-1]
        made = []
        for i, phys in enumerate(_expand(physical_channel)):
            chan_name = (name if i == 0 else f"{name}{i}") if name else phys
            made.append(_Chan(phys, chan_name, chassis.physical(phys), kind, **cfg))
        self._task._chans += made
        return AIChannel(made)

    def add_ai_accel_chan(self, physical_channel, name_to_assign_to_channel="",
                          terminal_config=TerminalConfiguration.DEFAULT, min_val=-5.0, max_val=5.0,
                          units=AccelUnits.G, sensitivity=1000.0,
                          sensitivity_units=AccelSensitivityUnits.MILLIVOLTS_PER_G,
                          current_excit_source=ExcitationSource.INTERNAL, current_excit_val=0.004,
                          custom_scale_name=""):
        return self._add(physical_channel, name_to_assign_to_channel, "accel", min_val=min_val, max_val=max_val,
                         units=units, sensitivity=sensitivity, sensitivity_units=sensitivity_units,
                         current_excit_source=current_excit_source, current_excit_val=current_excit_val)

    def add_ai_voltage_chan(self, physical_channel, name_to_assign_to_channel="",
                            terminal_config=TerminalConfiguration.DEFAULT, min_val=-5.0, max_val=5.0,
                            units=VoltageUnits.VOLTS, custom_scale_name=""):
        return self._add(physical_channel, name_to_assign_to_channel, "voltage", min_val=min_val, max_val=max_val,
                         units=units)


class Timing:
    def __init__(self, task: Task) -> None:
        self._task = task
        self._rate = None
        self.samp_quant_samp_mode = AcquisitionType.FINITE
        self.samp_quant_samp_per_chan = 1000

    def cfg_samp_clk_timing(self, rate, source="", active_edge=Edge.RISING, sample_mode=AcquisitionType.FINITE,
                            samps_per_chan=1000):
        self._rate = float(rate)
        self.samp_quant_samp_mode = sample_mode
        self.samp_quant_samp_per_chan = int(samps_per_chan)

    @property
    def samp_clk_rate(self) -> float:
        return coerce_rate(self._rate if self._rate is not None else VALID_RATES_HZ[0], self._task.name)

    @samp_clk_rate.setter
    def samp_clk_rate(self, value: float) -> None:
        self._rate = float(value)


class _Trigger:
    def __init__(self) -> None:
        self.trig_type = TriggerType.NONE
        self.source = ""
        self.rising = True
        self.level = 0.0
        self.pretrig_samples = 0


class StartTrigger(_Trigger):
    def cfg_dig_edge_start_trig(self, trigger_source, trigger_edge=Edge.RISING):
        self.trig_type, self.source, self.rising = TriggerType.DIGITAL_EDGE, trigger_source, trigger_edge == Edge.RISING

    def cfg_anlg_edge_start_trig(self, trigger_source="", trigger_slope=Slope.RISING, trigger_level=0.0):
        self.trig_type, self.source = TriggerType.ANALOG_EDGE, trigger_source
        self.rising, self.level = trigger_slope == Slope.RISING, float(trigger_level)

    def disable_start_trig(self):
        self.trig_type = TriggerType.NONE


class ReferenceTrigger(_Trigger):
    def cfg_anlg_edge_ref_trig(self, trigger_source, pretrigger_samples, trigger_slope=Slope.RISING,
                               trigger_level=0.0):
        self.trig_type, self.source, self.pretrig_samples = TriggerType.ANALOG_EDGE, trigger_source, pretrigger_samples
        self.rising, self.level = trigger_slope == Slope.RISING, float(trigger_level)

    def cfg_dig_edge_ref_trig(self, trigger_source, pretrigger_samples, trigger_edge=Edge.RISING):
        self.trig_type, self.source, self.pretrig_samples = TriggerType.DIGITAL_EDGE, trigger_source, pretrigger_samples
        self.rising = trigger_edge == Edge.RISING

    def disable_ref_trig(self):
        self.trig_type = TriggerType.NONE


class Triggers:
    def __init__(self) -> None:
        self.start_trigger = StartTrigger()
        self.reference_trigger = ReferenceTrigger()
