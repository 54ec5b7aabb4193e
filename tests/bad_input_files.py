"""Files the bad-input table's rows make (tests/test_bad_inputs.py): campaign files crafted by an attacker or a
careless tool, and NPZ and UFF files that announce more than they hold."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np

IMPACT = "series_01/run_01/step_001/impact_001"
FORCE = f"{IMPACT}/force_n"


def crafted(edit: Callable[[h5py.File, Path], None]) -> Callable[[Path], None]:
    """Edit the case's c.h5 in place (a file an attacker or a careless tool made); beside it a 'secret' file."""

    def make(folder: Path) -> None:
        (folder / "secret.bin").write_bytes(b"private data of someone else" * 4096)
        with h5py.File(folder / "c.h5", "r+") as f:
            edit(f, folder)

    return make


def replace_force(f: h5py.File, make: Callable[[h5py.Group, str, dict], None]) -> None:
    ds = f[FORCE]
    attrs = dict(ds.attrs)
    del f[FORCE]
    make(f[IMPACT], "force_n", attrs)


def external_storage(f: h5py.File, folder: Path) -> None:
    def make(g: h5py.Group, name: str, attrs: dict) -> None:
        ds = g.create_dataset(name, shape=(8192,), dtype="<f4", external=[(str(folder / "secret.bin"), 0, 32768)])
        ds.attrs.update({k: v for k, v in attrs.items() if k not in ("scale", "offset")})

    replace_force(f, make)


def virtual(f: h5py.File, folder: Path) -> None:
    with h5py.File(folder / "other.h5", "w") as o:
        o["x"] = np.arange(8192, dtype="<f4")

    def make(g: h5py.Group, name: str, attrs: dict) -> None:
        layout = h5py.VirtualLayout(shape=(8192,), dtype="<f4")
        layout[:] = h5py.VirtualSource(str(folder / "other.h5"), "x", shape=(8192,))
        g.create_virtual_dataset(name, layout)

    replace_force(f, make)


def external_link(f: h5py.File, folder: Path) -> None:
    with h5py.File(folder / "other.h5", "w") as o:
        o["x"] = np.arange(8192, dtype="<f4")
    replace_force(f, lambda g, name, attrs: g.__setitem__(name, h5py.ExternalLink(str(folder / "other.h5"), "/x")))


def soft_link(f: h5py.File, folder: Path) -> None:
    f["series_01/run_01/step_001/impact_002/force_n"]  # noqa: B018 — exists
    replace_force(f, lambda g, name, attrs: g.__setitem__(name, h5py.SoftLink(
        "/series_01/run_01/step_001/impact_002/force_n")))


def unknown_filter(f: h5py.File, folder: Path) -> None:
    def make(g: h5py.Group, name: str, attrs: dict) -> None:
        ds = g.create_dataset(name, data=np.zeros(8192, "<f4"), chunks=(8192,), compression=32004,
                              allow_unknown_filter=True)
        ds.attrs.update({k: v for k, v in attrs.items() if k not in ("scale", "offset")})

    replace_force(f, make)


def attr(name: str, value: object) -> Callable[[h5py.File, Path], None]:
    def edit(f: h5py.File, folder: Path) -> None:
        if value is None:
            del f[FORCE].attrs[name]
        else:
            f[FORCE].attrs[name] = value

    return edit


def log_entries_wrong(f: h5py.File, folder: Path) -> None:
    del f["log/entries"]
    f["log/entries"] = np.arange(3.0)


CHANNELS = np.array(["A1X", "A2X", "A3X", "A4X"])


def npz(name: str, edit: Callable[[bytearray], None] | None = None, *, compressed: bool = False,
         force: np.ndarray | None = None) -> Callable[[Path], None]:
    """An impacts NPZ (random samples, or ``force`` with silent accelerations), its bytes then edited (damaged)."""

    def make(folder: Path) -> None:
        rng = np.random.default_rng(1)
        f = rng.normal(size=(2, 4096)) if force is None else force
        save = np.savez_compressed if compressed else np.savez
        accel = rng.normal(size=(f.shape[0], 4, f.shape[1])) if force is None else np.zeros((f.shape[0], 4, f.shape[1]))
        save(folder / name, fs=np.float64(20480.0), force=f, accel=accel, channels=CHANNELS)
        if edit is not None:
            raw = bytearray((folder / name).read_bytes())
            edit(raw)
            (folder / name).write_bytes(bytes(raw))

    return make


def npz_huge_header(folder: Path) -> None:
    """'force' announces 10^13 float64 samples (73 TiB) in a 200-byte member."""
    import io
    import zipfile

    head = io.BytesIO()
    np.lib.format.write_array_header_1_0(head, {"descr": "<f8", "fortran_order": False, "shape": (10**13,)})
    with zipfile.ZipFile(folder / "huge.npz", "w") as z:
        z.writestr("force.npy", head.getvalue() + bytes(64))
        for key, value in (("fs", np.float64(20480.0)), ("accel", np.zeros((1, 4, 8))), ("channels", CHANNELS)):
            b = io.BytesIO()
            np.save(b, value)
            z.writestr(f"{key}.npy", b.getvalue())


def flip(at: float) -> Callable[[bytearray], None]:
    def edit(raw: bytearray) -> None:
        i = int(len(raw) * at)
        raw[i] ^= 0xFF
        raw[i + 1] ^= 0x55

    return edit


def uff_huge(folder: Path) -> None:
    """An exported UFF whose first data set's header announces 10^10 points."""
    from labctl.uff.writer import Selection, export_campaign

    export_campaign(folder / "c.h5", folder / "x.uff", selection=Selection(step=1), binary=False)
    lines = (folder / "x.uff").read_text().split("\n")
    i = next(k for k, line in enumerate(lines) if line.strip() == "58")
    count = lines[i + 7].split()[1]
    lines[i + 7] = lines[i + 7].replace(count.rjust(10), "9999999999", 1)
    (folder / "huge.uff").write_text("\n".join(lines))
    (folder / "x.uff").unlink()
