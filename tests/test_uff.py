"""UFF58 interchange: identify from UFF, export read-back (pyuff, sdypy-EMA), import with a manifest, bad input."""

from __future__ import annotations

import csv
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from labctl.uff import DEFAULT_NODES, NodeMap, parse_node_map, read_uff_impacts, sample_rate_hz
from labctl.uff.manifest import format_load_cases, parse_load_cases
from tests.cli_util import assert_one_line_error, labctl, labctl_here, labctl_here_json, labctl_json
from tests.engine_util import short_campaign_file

pyuff = pytest.importorskip("pyuff")


def write_foreign_uff(npz: Path, out: Path, *, binary: bool = False, nodes: NodeMap = DEFAULT_NODES,
                      load_cases: bool = True, accel_units: str = "m/s^2", accel_scale: float = 1.0,
                      flip: str | None = None) -> Path:
    """An impacts NPZ as another acquisition system would export it, written with pyuff's own API."""
    d = np.load(npz)
    fs, force, accel, channels = float(d["fs"]), d["force"], d["accel"], [str(c) for c in d["channels"]]
    n = force.shape[1]
    scratch = out.with_suffix(".set")
    out.write_bytes(b"")
    for i in range(force.shape[0]):
        lc = i + 1 if load_cases else 0
        records = [(nodes.hammer, 3, force[i], 13, "N")]
        for c, name in enumerate(channels):
            node, direction = nodes.node_dir(name)
            sign = -1.0 if name == flip else 1.0
            records.append((node, sign * direction, sign * accel[i, c] * accel_scale, 12, accel_units))
        for node, direction, y, ordinate, units in records:
            scratch.unlink(missing_ok=True)  # one set per pyuff call: it re-reads the whole file after each set
            pyuff.UFF(str(scratch)).write_sets(pyuff.prepare_58(
                binary=int(binary), func_type=1, load_case_id=lc, rsp_node=node, rsp_dir=int(direction),
                ref_node=nodes.hammer, ref_dir=3, data=np.asarray(y, dtype=float), x=np.arange(n) / fs,
                abscissa_spacing=1, abscissa_spec_data_type=17, ordinate_spec_data_type=ordinate,
                orddenom_spec_data_type=0, ordinate_axis_units_lab=units, id1="foreign system"), mode="add")
            with out.open("ab") as fh:
                fh.write(scratch.read_bytes())
    scratch.unlink()
    return out


@pytest.fixture(scope="module")
def impacts_npz(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("npz") / "x.npz"
    labctl_json("simulate", "impacts", "--roller-type", "1", "--load-n", "440", "--seed", "3", "--out", str(out))
    return out


@pytest.fixture(scope="module")
def short_npz(impacts_npz, tmp_path_factory) -> Path:
    """The same blows cut to 0.8 s (the response has died out by then): small files for the UFF round trips."""
    d = np.load(impacts_npz)
    out = tmp_path_factory.mktemp("npz") / "short.npz"
    np.savez(out, fs=d["fs"], force=d["force"][:, :16384], accel=d["accel"][..., :16384], channels=d["channels"])
    return out


@pytest.fixture(scope="module")
def foreign(short_npz, tmp_path_factory) -> dict[bool, Path]:
    """The short blows as another system's UFF, ASCII (False) and binary (True), each written once: pyuff's writer
    re-reads the whole file after every set, so a file costs about half a second."""
    folder = tmp_path_factory.mktemp("foreign")
    return {binary: write_foreign_uff(short_npz, folder / f"{binary}.uff", binary=binary) for binary in (False, True)}


def copy_of(foreign: dict[bool, Path], dest: Path, *, binary: bool) -> Path:
    """This test's own copy of the foreign file, under the name it uses."""
    shutil.copyfile(foreign[binary], dest)
    return dest


@pytest.fixture(scope="module")
def campaign(tmp_path_factory) -> Path:
    return short_campaign_file(tmp_path_factory.mktemp("campaign") / "c.h5", seed=5)


@pytest.mark.parametrize("binary", [False, True])
def test_uff_written_by_pyuff_identifies_like_the_npz(short_npz, foreign, tmp_path, binary, capsys):
    uff = copy_of(foreign, tmp_path / "x.uff", binary=binary)
    from_npz = labctl_here_json(capsys, "identify", str(short_npz))
    from_uff = labctl_here_json(capsys, "identify", str(uff))
    assert from_uff["fs_hz"] == 20480.0  # recovered from the 6-digit interval 4.88281e-05 s
    assert from_uff["bounce_hz"] == pytest.approx(from_npz["bounce_hz"], abs=0.01)
    assert from_uff["roller_stiffness_n_per_m"] == pytest.approx(from_npz["roller_stiffness_n_per_m"], rel=1e-4)
    assert from_uff["channels"] == from_npz["channels"]


def test_foreign_conventions_nodes_units_signs_and_unnumbered_load_cases(short_npz, tmp_path):
    nodes = parse_node_map("A1=101,A2=102,A3=103,A4=104,hammer=1")
    uff = write_foreign_uff(short_npz, tmp_path / "pak.uff", nodes=nodes, load_cases=False, accel_units="g",
                            accel_scale=1 / 9.80665, flip="A2Z")
    got = read_uff_impacts(uff, nodes)
    d = np.load(short_npz)
    assert got.channels == tuple(str(c) for c in d["channels"])
    assert got.load_cases == [1, 2, 3] and any("file order" in n for n in got.notes)
    np.testing.assert_allclose(got.force_n, d["force"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(got.accel_m_per_s2, d["accel"], rtol=1e-9, atol=1e-9)  # g → m/s², −Z → +Z
    assert len(read_uff_impacts(uff, nodes, load_cases=[2]).load_cases) == 1


def test_unmapped_nodes_are_left_out_and_said(short_npz, tmp_path):
    uff = write_foreign_uff(short_npz, tmp_path / "x.uff", nodes=parse_node_map("A4=7"), binary=True)
    got = read_uff_impacts(uff)
    assert "A4Z" not in got.channels and len(got.channels) == 9
    assert any("node 7" in n for n in got.notes)


def _read_all(path: Path) -> list[dict]:
    return pyuff.UFF(str(path)).read_sets()


@pytest.mark.parametrize("binary", [False, True])
def test_export_reads_back_through_pyuff_exactly(campaign, tmp_path, binary, capsys):
    from labctl.storage import CampaignReader

    out = tmp_path / "e.uff"
    args = ["export", str(campaign), "--uff", str(out), "--run", "2", "--step", "2"] + (["--binary"] * binary)
    res = labctl_here_json(capsys, *args)
    assert res["impacts"] == 2 and res["frfs"] == 12 and res["format"] == ("58b" if binary else "58")
    sets = _read_all(out)
    assert len(sets) == res["sets"]
    with CampaignReader(campaign) as r:
        imp = r.impact_arrays(1, 2, 2, accepted_only=True)
        freqs, h1, coh = r.step_frf(1, 2, 2)
    worst = 0.0
    time_sets = [s for s in sets if s["func_type"] == 1]
    for i in range(2):
        force = next(s for s in time_sets if s["load_case_id"] == i + 1 and s["rsp_node"] == 10)
        assert force["ordinate_spec_data_type"] == 13 and force["rsp_dir"] == 3
        worst = max(worst, _rel(force["data"], imp.force_n[i]))
        for c, name in enumerate(imp.channels):
            node, direction = int(name[1]), "XYZ".index(name[2]) + 1
            s = next(s for s in time_sets if s["load_case_id"] == i + 1 and s["rsp_node"] == node
                     and s["rsp_dir"] == direction)
            assert s["ordinate_spec_data_type"] == 12
            worst = max(worst, _rel(s["data"], imp.accel_m_per_s2[i, c]))
    frfs = [s for s in sets if s["func_type"] == 4]
    for c, s in enumerate(frfs):
        worst = max(worst, _rel(s["data"], h1[c].astype(complex)))
    cohs = [s for s in sets if s["func_type"] == 6]
    worst = max(worst, *(_rel(s["data"], coh[c]) for c, s in enumerate(cohs)))
    assert worst < 1e-9
    assert sample_rate_hz(time_sets[0]["abscissa_inc"]) == imp.sample_rate_hz
    np.testing.assert_allclose(frfs[0]["x"], freqs, rtol=1e-5)


def _rel(got: np.ndarray, want: np.ndarray) -> float:
    want = np.asarray(want)
    nz = want != 0
    assert np.all(np.asarray(got)[~nz] == 0)
    return float(np.max(np.abs(got[nz] - want[nz]) / np.abs(want[nz]))) if nz.any() else 0.0


def test_export_reads_back_through_sdypy_ema(campaign, tmp_path, capsys):
    ema = pytest.importorskip("sdypy.EMA")
    out = tmp_path / "frf.uff"
    labctl_here_json(capsys, "export", str(campaign), "--uff", str(out), "--run", "1", "--step", "2", "--no-time",
                     "--binary")
    model = ema.Model(lower=50, upper=2000, pol_order_high=10)
    model.read_uff(str(out))
    from labctl.storage import CampaignReader

    with CampaignReader(campaign) as r:
        freqs, h1, _ = r.step_frf(1, 1, 2)
    keep = freqs <= model.freq[-1]
    assert model.frf_form == "accelerance" and model.frf.shape == (12, int(keep.sum()))
    np.testing.assert_allclose(model.frf, h1[:, keep], rtol=1e-6)


def test_export_and_import_with_the_manifest_reproduce_the_campaign(campaign, tmp_path, capsys):
    uff, manifest, back = tmp_path / "all.uff", tmp_path / "m.csv", tmp_path / "back.h5"
    labctl_here_json(capsys, "export", str(campaign), "--uff", str(uff), "--binary", "--manifest", str(manifest),
                     "--no-frf")
    with manifest.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["repetition"] for r in rows} == {"1", "2"} and rows[0]["load_cases"] == "1-2"
    res = labctl_json("import", str(uff), "--manifest", str(manifest), "--out", str(back))
    assert res["identified"] == len(rows)
    original = labctl_here_json(capsys, "process", str(campaign))["steps"]
    imported = labctl_here_json(capsys, "process", str(back))["steps"]
    assert [(s["run"], s["step"]) for s in imported] == [(s["run"], s["step"]) for s in original]
    for a, b in zip(original, imported, strict=True):
        assert b["load_n"] == pytest.approx(a["load_n"], rel=1e-9)
        assert b["bounce_hz"] == pytest.approx(a["bounce_hz"], rel=1e-9)
        # the mean of three per-roller stiffnesses leans on the tilt pair: UFF's single-precision samples move it
        assert b["roller_stiffness_n_per_m"] == pytest.approx(a["roller_stiffness_n_per_m"], rel=1e-6)
    from labctl.storage import CampaignReader

    with CampaignReader(back) as r:
        assert r.attrs["backend"] == "import" and "load_n" in (r.config_text("manifest.csv") or "")
        curve = r.curve(1, 2)
    assert curve is not None and len(curve["load_n"]) == sum(1 for s in original if s["run"] == 2)


def test_import_of_a_foreign_file_with_a_hand_written_manifest(short_npz, foreign, tmp_path, capsys):
    uff = copy_of(foreign, tmp_path / "pak.uff", binary=True)
    manifest = tmp_path / "m.csv"
    manifest.write_text("load_cases,load_n,repetition\n1-2,440,1\n3,440,2\n", encoding="utf-8")
    res = labctl_here_json(capsys, "import", str(uff), "--manifest", str(manifest), "--out", str(tmp_path / "c.h5"),
                           "--roller-type", "1")
    assert [(s["run"], s["impacts"]) for s in res["steps"]] == [(1, 2), (2, 1)]
    npz = labctl_here_json(capsys, "identify", str(short_npz))
    # two of the three blows: the twin's nonlinear contact moves the bounce with the blows, within its stated 1-σ
    assert abs(res["steps"][0]["bounce_hz"] - npz["bounce_hz"]) <= 0.05 + 2 * npz["bounce_hz_std"]


def test_manifest_and_option_errors_name_the_row_and_column(foreign, tmp_path):
    from labctl.errors import InputError
    from labctl.uff.importer import ImportOptions, import_uff

    uff = copy_of(foreign, tmp_path / "x.uff", binary=True)
    out = tmp_path / "c.h5"
    manifest = tmp_path / "m.csv"
    cases = [
        ("load_n\n440\n", "missing column(s) repetition"),
        ("load_n,repetition\n-4,1\n", "row 2, column load_n"),
        ("load_cases,load_n,repetition\n3-1,440,1\n", "row 2, column load_cases"),
        ("load_cases,load_n,repetition\n1-2,440,1\n2-3,500,1\n", "load case 2 of x.uff is also used by row 2"),
        ("load_cases,load_n,repetition\n1-2,440,1\n,500,1\n", "row 3 takes every impact"),
        ("load_cases,load_n,repetition,step\n1,440,1,1\n2,500,1,1\n", "appears twice"),
        ("load_cases,load_n,repetition\n7,440,1\n", "load case(s) [7]"),
        ("file,load_n,repetition\nother.uff,440,1\n", "'other.uff' is none of the files"),
        ("load_n,repetition,colour\n440,1,red\n", "unknown column(s) colour"),
        ("load_n,repetition,roller_type\n440,1,99\n", "99"),
        ("load_n,repetition,rail_ra_um\n440,1,1e300\n", "column rail_ra_um: '1e300' is not a rail Ra in [0, 50]"),
        ("load_n,repetition\n1,440,1\n", "row 2: 3 fields, the header has 2"),
    ]
    for text, fragment in cases:
        manifest.write_text(text, encoding="utf-8")
        with pytest.raises(InputError) as err:
            import_uff([uff], manifest, out, ImportOptions(roller_type=1))
        assert fragment in str(err.value) and str(manifest) in str(err.value), (fragment, str(err.value))
        assert not out.exists()
    manifest.write_text("load_n,repetition\n440,1\n", encoding="utf-8")
    with pytest.raises(InputError, match="no roller type"):
        import_uff([uff], manifest, out)
    proc = labctl("import", str(uff), "--manifest", str(manifest), "--out", str(out), "--nodes", "A1=x")
    assert_one_line_error(proc, "node map entry")


def test_corrupt_and_truncated_uff_files_are_refused(foreign, tmp_path, capsys):
    from labctl.errors import InputError
    from labctl.uff import load_impacts_uff

    good = copy_of(foreign, tmp_path / "good.uff", binary=False)
    data = good.read_bytes()
    truncated = tmp_path / "cut.uff"
    truncated.write_bytes(data[: len(data) // 2])
    junk = tmp_path / "junk.uff"
    junk.write_bytes(b"\x00\x01 not a universal file\n" * 50)
    garbled = tmp_path / "garbled.uff"
    lines = data.split(b"\n")
    lines[15] = b"    this is not a number"
    garbled.write_bytes(b"\n".join(lines))
    short = tmp_path / "short.uff"  # a header that promises more samples than the set holds
    short.write_bytes(data.replace(b"     16384         1", b"     16390         1"))
    spectra = tmp_path / "frf.uff"
    spectra.write_bytes(re.sub(rb"(?m)^    1(         0    0 )", rb"    4\1", data))  # every set an FRF
    for path, fragment in ((truncated, "truncated"), (junk, "not a UFF file"), (garbled, "cannot be read"),
                           (short, "header announces 16390"), (spectra, "no UFF58 time records"),
                           (tmp_path / "none.uff", "not found")):
        with pytest.raises(InputError, match=fragment) as err:
            load_impacts_uff(path)
        assert path.name in str(err.value)
    assert_one_line_error(labctl("identify", str(truncated)), "cut.uff", "truncated")
    manifest = tmp_path / "m.csv"
    manifest.write_text("load_n,repetition\n440,1\n", encoding="utf-8")
    proc = labctl_here(capsys, "import", str(garbled), "--manifest", str(manifest), "--out", str(tmp_path / "c.h5"),
                       "--roller-type", "1")
    assert_one_line_error(proc, "garbled.uff")
    assert not (tmp_path / "c.h5").exists()


def test_export_of_corrupt_or_truncated_campaigns_fails_with_one_line(campaign, tmp_path, capsys):
    cut = tmp_path / "cut.h5"
    cut.write_bytes(campaign.read_bytes()[:5000])
    assert_one_line_error(labctl("export", str(cut), "--uff", str(tmp_path / "o.uff")), "cut.h5")
    assert_one_line_error(labctl_here(capsys, "export", str(tmp_path / "missing.h5"), "--uff",
                                      str(tmp_path / "o.uff")), "missing.h5", "not found")
    assert not (tmp_path / "o.uff").exists()
    assert_one_line_error(labctl_here(capsys, "export", str(campaign), "--uff", str(tmp_path / "o.uff"), "--run", "9"),
                          "no stored step matches run 9")
    assert_one_line_error(labctl_here(capsys, "export", str(campaign), "--uff", str(tmp_path / "o.uff"), "--no-time",
                                      "--no-frf"), "nothing to export")
    two = tmp_path / "two.uff"
    labctl_here_json(capsys, "export", str(campaign), "--uff", str(two), "--run", "1", "--binary", "--no-frf")
    assert_one_line_error(labctl_here(capsys, "identify", str(two)), "load steps", "--step")


def test_sample_rate_recovered_from_six_digit_intervals():
    assert sample_rate_hz(float(f"{1 / 20480:.5e}")) == 20480.0
    assert sample_rate_hz(float(f"{1 / 25600:.5e}")) == 25600.0
    assert sample_rate_hz(1 / 20480) == 20480.0
    ni = 51200 / 3  # an NI 9234 rate: not round, recovered within what six digits allow
    assert sample_rate_hz(float(f"{1 / ni:.5e}")) == pytest.approx(ni, rel=2e-6)


def test_load_case_lists_and_node_maps():
    assert parse_load_cases("1-3;7 9|10") == (1, 2, 3, 7, 9, 10)
    assert format_load_cases([10, 9, 7, 1, 2, 3]) == "1-3;7;9-10"
    for bad in ("", "3-1", "a", "1;1"):
        with pytest.raises(ValueError):
            parse_load_cases(bad)
    nodes = parse_node_map("A1=101,hammer=1")
    assert nodes.node_dir("A1Y") == (101, 2) and nodes.node_dir("A2Z") == (2, 3)
    assert nodes.channel(101, -3) == ("A1Z", -1.0) and nodes.channel(1, 3) is None
    with pytest.raises(ValueError, match="own node"):
        parse_node_map("A1=10")


@pytest.mark.parametrize("binary", [False, True])
def test_fast_reader_decodes_every_set_exactly_as_pyuff(campaign, foreign, tmp_path, binary, capsys):
    """The vectorised decoding (58b by byte count, ASCII in one call) agrees with pyuff value for value."""
    from labctl.uff import UffFile

    theirs = copy_of(foreign, tmp_path / "f.uff", binary=binary)
    ours = tmp_path / "e.uff"  # real time records, complex FRFs and coherences
    labctl_here_json(capsys, "export", str(campaign), "--uff", str(ours), "--run", "1", "--step", "1",
                     "--binary" if binary else "--ascii")
    for path in (theirs, ours):
        uff = UffFile(path)
        want = _read_all(path)
        assert len(uff.headers) == len(want)
        for h, w in zip(uff.headers, want, strict=True):
            x, y = uff.data(h)
            assert h.binary == binary and h.num_pts == w["num_pts"] and h.node == w["rsp_node"]
            np.testing.assert_array_equal(y, w["data"])
            np.testing.assert_allclose(x, w["x"], rtol=1e-12)
        uff.close()


def test_binary_values_that_look_like_a_delimiter_do_not_split_a_set(tmp_path):
    """Eight bytes of a double can read '\\n    -1\\n'; 58b sets are skipped by their size, not searched."""
    from labctl.uff import UffFile

    trap = float(np.frombuffer(b"\n    -1\n", "<f8")[0])
    y = np.array([1.0, trap, -2.5, trap, 3.0])
    path = tmp_path / "trap.uff"
    for node in (10, 1):
        pyuff.UFF(str(path)).write_sets(pyuff.prepare_58(
            binary=1, func_type=1, load_case_id=1, rsp_node=node, rsp_dir=3, ref_node=10, ref_dir=3, data=y,
            x=np.arange(5) / 20480.0, abscissa_spacing=1, abscissa_spec_data_type=17,
            ordinate_spec_data_type=13 if node == 10 else 12, orddenom_spec_data_type=0), mode="add")
    uff = UffFile(path)
    assert [h.node for h in uff.headers] == [10, 1]
    for h in uff.headers:
        np.testing.assert_array_equal(uff.data(h)[1], y)
    uff.close()


def test_large_exports_default_to_binary_and_progress_is_reported(campaign, tmp_path, monkeypatch):
    from labctl.uff import writer
    from labctl.uff.importer import import_uff

    calls: list[tuple[int, int]] = []
    small = writer.export_campaign(campaign, tmp_path / "s.uff", selection=writer.Selection(run=1, frf=False),
                                   manifest=tmp_path / "m.csv", progress=lambda d, t: calls.append((d, t)))
    assert not small.binary  # a few MB: ASCII, readable by any tool
    assert calls[-1] == (small.steps, small.steps) and [d for d, _ in calls] == list(range(small.steps + 1))
    monkeypatch.setattr(writer, "ASCII_LIMIT_BYTES", 1e5)
    big = writer.export_campaign(campaign, tmp_path / "b.uff", selection=writer.Selection(run=1, frf=False))
    assert big.binary and (tmp_path / "b.uff").read_bytes().splitlines()[1].split()[0] == b"58b"
    steps: list[tuple[int, int]] = []
    import_uff([tmp_path / "s.uff"], tmp_path / "m.csv", tmp_path / "c.h5", progress=lambda d, t: steps.append((d, t)))
    assert steps[0] == (0, small.steps) and steps[-1] == (small.steps, small.steps)
