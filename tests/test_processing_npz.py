"""The impacts NPZ reader: round trip and every way a file can be wrong, each named."""

from __future__ import annotations

import numpy as np
import pytest

from labctl.errors import InputError
from labctl.processing import load_impacts_npz

CHANNELS = np.array(["A1X", "A1Z", "A4Z"])


def write(path, **over):
    arrays = {"fs": np.float64(20480.0), "force": np.zeros((2, 64)), "accel": np.zeros((2, 3, 64)),
              "channels": CHANNELS}
    arrays.update(over)
    np.savez(path, **{k: v for k, v in arrays.items() if v is not None})
    return path


def test_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    force, accel = rng.normal(size=(2, 64)), rng.normal(size=(2, 3, 64))
    s = load_impacts_npz(write(tmp_path / "ok.npz", force=force, accel=accel))
    assert s.fs_hz == 20480.0 and s.channels == ("A1X", "A1Z", "A4Z")
    np.testing.assert_array_equal(s.force_n, force)
    np.testing.assert_array_equal(s.accel_m_per_s2, accel)


@pytest.mark.parametrize("key", ["fs", "force", "accel", "channels"])
def test_missing_key_is_named(tmp_path, key):
    with pytest.raises(InputError, match=f"missing key '{key}'"):
        load_impacts_npz(write(tmp_path / "m.npz", **{key: None}))


@pytest.mark.parametrize("over, fragment", [
    ({"force": np.zeros(64)}, "'force' has shape (64,)"),
    ({"accel": np.zeros((2, 64))}, "'accel' has shape (2, 64)"),
    ({"accel": np.zeros((3, 3, 64))}, "expected accel shaped (2, n_channels, 64)"),
    ({"accel": np.zeros((2, 3, 65))}, "expected accel shaped (2, n_channels, 64)"),
    ({"channels": np.array(["A1X", "A1Z"])}, "names 2 channels but 'accel' has 3"),
    ({"channels": np.array(["A1X", "A1X", "A4Z"])}, "repeats A1X"),
    ({"channels": np.array([1, 2, 3])}, "'channels' has shape (3,) and dtype int64"),
    ({"fs": np.array([20480.0, 1.0])}, "'fs' = [20480.0, 1.0]"),
    ({"fs": np.float64(-5.0)}, "expected one positive sample rate"),
    ({"force": np.full((2, 64), np.nan)}, "'force' holds a non-finite value at index (0, 0)"),
    ({"accel": np.zeros((2, 3, 0)), "force": np.zeros((2, 0))}, "'force' is empty"),
])
def test_wrong_shapes_and_values_are_named(tmp_path, over, fragment):
    with pytest.raises(InputError) as err:
        load_impacts_npz(write(tmp_path / "bad.npz", **over))
    assert fragment in str(err.value)
    assert str(tmp_path / "bad.npz") in str(err.value)


def test_pickled_objects_are_refused_without_running_them(tmp_path):
    path = tmp_path / "pickled.npz"
    np.savez(path, fs=np.float64(20480.0), force=np.zeros((1, 8)), accel=np.zeros((1, 1, 8)),
             channels=np.array([{"name": "A1Z"}], dtype=object))
    with pytest.raises(InputError, match="'channels' holds pickled Python objects"):
        load_impacts_npz(path)


def test_not_an_npz_and_missing_file(tmp_path):
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip at all")
    with pytest.raises(InputError, match="not a readable NPZ"):
        load_impacts_npz(junk)
    single = tmp_path / "single.npy"
    np.save(single, np.zeros(3))
    with pytest.raises(InputError, match="single array"):
        load_impacts_npz(single)
    with pytest.raises(InputError, match="file not found"):
        load_impacts_npz(tmp_path / "nope.npz")
