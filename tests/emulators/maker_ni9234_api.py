"""The names and values of the ``nidaqmx`` package the NI 9234 emulator (``maker_ni9234.py``) installs: its
``constants`` enums and its ``errors`` / ``error_codes`` classes, as in the real package (facts:
tests/emulators/MAKER_FACTS.md)."""

from __future__ import annotations

from enum import Enum

READ_ALL_AVAILABLE = -1
WAIT_INFINITELY = -1.0


# -- nidaqmx.constants (values as in the real package) ---------------------------------------------------------------
class AcquisitionType(Enum):
    FINITE = 10178
    CONTINUOUS = 10123
    HW_TIMED_SINGLE_POINT = 12522


class AccelUnits(Enum):
    G = 10186
    METERS_PER_SECOND_SQUARED = 12470
    INCHES_PER_SECOND_SQUARED = 12471
    FROM_CUSTOM_SCALE = 10065


class AccelSensitivityUnits(Enum):
    MILLIVOLTS_PER_G = 12509
    VOLTS_PER_G = 12510
    M_VOLTS_PER_G = 12509  # the spelling of older nidaqmx releases (an alias of the same value)


class Coupling(Enum):
    AC = 10045
    DC = 10050
    GND = 10066


class Edge(Enum):
    RISING = 10280
    FALLING = 10171


class Slope(Enum):
    RISING = 10280
    FALLING = 10171


class ExcitationSource(Enum):
    INTERNAL = 10200
    EXTERNAL = 10167
    NONE = 10230


class TerminalConfiguration(Enum):
    RSE = 10083
    NRSE = 10078
    DIFF = 10106
    PSEUDO_DIFF = 12529
    DEFAULT = -1


class TriggerType(Enum):
    ANALOG_EDGE = 10099
    DIGITAL_EDGE = 10150
    NONE = 10230


class VoltageUnits(Enum):
    VOLTS = 10348
    FROM_CUSTOM_SCALE = 10065


# -- nidaqmx.errors / error_codes --------------------------------------------------------------------------------------
class DAQmxErrors(Enum):
    UNKNOWN = -1
    INVALID_ATTRIBUTE_VALUE = -200077
    PHYSICAL_CHAN_DOES_NOT_EXIST = -200170
    TOO_MANY_PRETRIG_PLUS_MIN_POST_TRIG_SAMPS = -200213
    INVALID_ANALOG_TRIG_SRC = -200265
    SAMPLES_WILL_NEVER_BE_AVAILABLE = -200278
    SAMPLES_NOT_YET_AVAILABLE = -200284
    REF_TRIG_WHEN_CONTINUOUS = -200358
    WAIT_UNTIL_DONE_DOES_NOT_INDICATE_DONE = -200560


class Error(Exception):
    pass


class DaqError(Error):
    """Same constructor and properties as nidaqmx.errors.DaqError."""

    def __init__(self, message: str, error_code: int, task_name: str = "") -> None:
        if task_name:
            message = f"{message}\n\nTask Name: {task_name}"
        super().__init__(message)
        self._error_code = int(error_code)
        try:
            self._error_type = DAQmxErrors(self._error_code)
        except ValueError:
            self._error_type = DAQmxErrors.UNKNOWN

    @property
    def error_code(self) -> int:
        return self._error_code

    @property
    def error_type(self) -> DAQmxErrors:
        return self._error_type


class DaqReadError(DaqError):
    def __init__(self, message: str, error_code: int, samps_per_chan_read: int, task_name: str = "") -> None:
        super().__init__(message, error_code, task_name)
        self.samps_per_chan_read = samps_per_chan_read
