"""Per-channel accelerometer cross-axis values in the devices file reach the per-roller σ: the sensor holding the
channel takes the (largest) value given, the cross-axis variance of its channels grows with it, and a devices
file without them leaves the rig as it is."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from labctl.data import data_path
from labctl.hardware import rig_with_channel_cross_axis
from labctl.physics import load_rig
from labctl.processing.cross_axis import cross_axis_variance

EXAMPLE = data_path("devices.example.toml").read_text(encoding="utf-8")


def with_line(channel: str, line: str) -> str:
    at = EXAMPLE.index(f'name = "{channel}"')
    return EXAMPLE[:at] + line + "\n" + EXAMPLE[at:]


def test_a_channels_transverse_sensitivity_sets_its_sensors_and_widens_its_variance():
    rig = load_rig()
    text = with_line("A1X", "transverse_sensitivity = 0.10\nmounting_angle_deg = 5.0")
    tuned = rig_with_channel_cross_axis(rig, text, "d.toml")
    by_name = {s.name: s for s in tuned.sensors}
    assert by_name["A1"].transverse_sensitivity == 0.10
    assert by_name["A1"].mounting_angle_rad == pytest.approx(math.radians(5.0))
    assert all(by_name[n] == s for n, s in ((s.name, s) for s in rig.sensors) if n != "A1")
    names = ("A1Z", "A1X", "A1Y", "A2Z", "A2X", "A2Y")
    constants = np.ones((2, len(names)))
    before, after = cross_axis_variance(rig, names, constants), cross_axis_variance(tuned, names, constants)
    u = rig.uncertainty
    ratio = (0.10**2 + math.sin(math.radians(5.0)) ** 2) / (u.transverse_sensitivity**2
                                                          + math.sin(u.mounting_angle_rad) ** 2)
    np.testing.assert_allclose(after[:, :3], before[:, :3] * ratio, rtol=1e-12)
    np.testing.assert_allclose(after[:, 3:], before[:, 3:], rtol=1e-12)


def test_a_devices_file_without_the_keys_leaves_the_rig():
    rig = load_rig()
    assert rig_with_channel_cross_axis(rig, EXAMPLE, "d.toml") is rig


class _StoredConfig:
    """The two calls ``rig_of`` makes on a campaign reader, over stored configuration texts."""

    path = "c.h5"

    def __init__(self, files: dict[str, str]) -> None:
        self.files = files

    def config_text(self, name: str) -> str:
        return self.files.get(name, "")

    def required_config(self, name: str) -> str:
        return self.files[name]


def test_a_campaigns_stored_devices_file_reaches_the_rig_it_is_processed_with():
    from labctl.reprocess import rig_of

    rig_text = Path(load_rig().source).read_text(encoding="utf-8")
    plain = rig_of(_StoredConfig({"rig.toml": rig_text}))
    tuned = rig_of(_StoredConfig({"rig.toml": rig_text,
                                  "devices.toml": with_line("A2Z", "transverse_sensitivity = 0.2")}))
    assert {s.name: s.transverse_sensitivity for s in tuned.sensors}["A2"] == 0.2
    assert {s.name: s.transverse_sensitivity for s in plain.sensors}["A2"] is None
