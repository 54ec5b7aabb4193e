"""The bad-input table: every row is (name, files to make, command, fragments of the expected one-line error).

Each case runs in this process (``labctl.cli.main``) in a fresh folder holding a small complete campaign
``c.h5`` (and whatever the row's ``make`` adds); the command must exit 2 with exactly one line on stderr
holding every fragment, no traceback, and must leave every file that existed before byte for byte as it was
(no output overwrites an input; no crafted input changes anything). A new case is one line in CASES.
"""

from __future__ import annotations

import hashlib
import shutil
import sqlite3
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.bad_input_files import (
    FORCE,
    attr,
    crafted,
    external_link,
    external_storage,
    flip,
    log_entries_wrong,
    npz,
    npz_huge_header,
    soft_link,
    uff_huge,
    unknown_filter,
    virtual,
)
from tests.cli_util import assert_one_line_error, labctl_here


@dataclass(frozen=True)
class Case:
    name: str
    argv: str  # split on spaces; files are relative to the case folder
    fragments: tuple[str, ...]
    make: Callable[[Path], None] | None = None


def _foreign_db(folder: Path) -> None:
    """Another application's SQLite file with tables and views labctl does not know."""
    conn = sqlite3.connect(folder / "other.db")
    with conn:
        conn.executescript("CREATE TABLE a (x); CREATE TABLE b (y); CREATE TABLE c (z); "
                           "CREATE VIEW v1 AS SELECT * FROM a; CREATE VIEW v2 AS SELECT * FROM b; "
                           "INSERT INTO a VALUES (1);")
    conn.close()


def _newer_catalogue(folder: Path) -> None:
    """A labctl catalogue of a schema version newer than this labctl writes."""
    _catalogue(folder)
    conn = sqlite3.connect(folder / "arc.db")
    with conn:
        conn.execute("UPDATE catalogue_info SET value = '99' WHERE key = 'schema_version'")
    conn.close()


def _link(name: str, target: str) -> Callable[[Path], None]:
    return lambda folder: (folder / name).symlink_to(target)


def _hard_link(name: str, target: str) -> Callable[[Path], None]:
    return lambda folder: (folder / name).hardlink_to(folder / target)


def _text(name: str, text: str) -> Callable[[Path], None]:
    return lambda folder: (folder / name).write_text(text, encoding="utf-8")


def _world(expression: str) -> Callable[[Path], None]:
    return _text("w.toml", f'[baseline]\nmodel = "expression"\nexpression = "{expression}"\n')


def _review(series: int = 1, run: int = 1, step: int = 1, attempt: int = 1) -> Callable[[Path], None]:
    return _text("op.toml", f"[[review]]\nseries = {series}\nrun = {run}\nstep = {step}\nattempt = {attempt}\n"
                            'verdict = "reject"\nreason = "the hammer slipped"\n')


BALL_PROTOCOL = """[protocol]
name = "one_ball"
description = "a 6 mm ball, short records"
version = 1

[specimen]
kind = "ball"
ball_diameter_mm = 6.0
rail_ra_um = 0.03
max_load_n = 120.0
knob_step_deg = 360.0

[acquisition]
samples = 8192
impacts_per_step = 2

[repetitions]
count = 1
"""


def _ball_campaign(folder: Path) -> None:
    from labctl.campaign import run_campaign

    (folder / "ball.toml").write_text(BALL_PROTOCOL, encoding="utf-8")
    assert run_campaign(folder / "ball.toml", out=folder / "b.h5", backend="sim", seed=2).status == "complete"


def _catalogue(folder: Path) -> None:
    from labctl.archive import index

    index(folder / "arc.db", [folder / "c.h5"])


RUN = "run quick_check --out n.h5 --quiet"
TABLE_HEAD = "diameter_mm,contact_length_mm,rail_ra_um,load_n,stiffness_n_per_m\n"
BIG_LOAD_TABLE = f"{TABLE_HEAD}10,10,0.2,100,5e8\n10,10,0.2,1e6,6e8\n"
CASES = [
    # an output naming an input (or linking to it) is refused before anything is written
    Case("process csv over campaign", "process c.h5 --csv c.h5", ("--csv c.h5", "is the input c.h5")),
    Case("process csv symlink to campaign", "process c.h5 --csv l.csv", ("--csv l.csv", "is the input"),
         _link("l.csv", "c.h5")),
    Case("process csv hard link to campaign", "process c.h5 --csv h.csv", ("--csv h.csv", "is the input"),
         _hard_link("h.csv", "c.h5")),
    Case("process csv over another campaign", "process c.h5 --csv d.h5", ("--csv d.h5", "HDF5"),
         lambda f: shutil.copy(f / "c.h5", f / "d.h5")),
    Case("export uff over campaign", "export c.h5 --uff c.h5", ("--uff c.h5", "is the input c.h5")),
    Case("export manifest over campaign", "export c.h5 --uff e.uff --manifest c.h5",
         ("--manifest c.h5", "is the input c.h5")),
    Case("export manifest over its uff", "export c.h5 --uff e.uff --manifest e.uff",
         ("--manifest e.uff", "also the output of --uff")),
    Case("calibrate out over campaign", "calibrate c.h5 --out c.h5", ("--out c.h5", "is the input c.h5")),
    Case("calibrate out over nominal rig", "calibrate c.h5 --rig r.toml --out r.toml",
         ("--out r.toml", "is the input r.toml"), _text("r.toml", "name = 'x'\n")),
    Case("run out over its protocol", "run p.toml --out p.toml --resume", ("--out p.toml", "is the input p.toml"),
         _text("p.toml", "[protocol]\nname = 'x'\n")),
    Case("report into the campaign's own name", "report report.html --out .",
         ("--out .", "is the input report.html"), lambda f: shutil.copy(f / "c.h5", f / "report.html")),
    Case("archive query csv over catalogue", "archive query --csv arc.db --db arc.db",
         ("--csv arc.db", "is the input arc.db"), _catalogue),
    Case("archive index db over a campaign", "archive index c.h5 --db c.h5", ("--db c.h5", "is the input")),
    # --db on a file that is not a labctl catalogue is refused before it is touched
    Case("archive index foreign sqlite", "archive index c.h5 --db other.db",
         ("--db other.db", "another application"), _foreign_db),
    Case("archive query foreign sqlite", "archive query --db other.db", ("--db other.db", "another application"),
         _foreign_db),
    Case("archive process into a foreign sqlite", "archive process c.h5 --workers 0 --db other.db --quiet",
         ("--db other.db", "another application"), _foreign_db),
    Case("archive index into a newer catalogue", "archive index c.h5 --db arc.db",
         ("--db arc.db", "schema version 99", "not changed"), _newer_catalogue),
    Case("archive index text file as db", "archive index c.h5 --db notes.db", ("--db notes.db", "not an SQLite"),
         _text("notes.db", "shopping list\n")),
    # a crafted campaign never makes labctl read another file, load a plug-in, or use unreadable values
    Case("process external storage", "process c.h5", (FORCE, "external file", "secret.bin"),
         crafted(external_storage)),
    Case("export external storage", "export c.h5 --uff e.uff", (FORCE, "external file"), crafted(external_storage)),
    Case("report external storage", "report c.h5 --out r", (FORCE, "external file"), crafted(external_storage)),
    Case("process virtual dataset", "process c.h5", (FORCE, "virtual dataset"), crafted(virtual)),
    Case("process external link", "process c.h5", (FORCE, "external link", "other.h5"), crafted(external_link)),
    Case("resume external link", "run quick_check --out c.h5 --resume", (FORCE, "external link"),
         crafted(external_link)),
    Case("process soft link", "process c.h5", (FORCE, "soft link"), crafted(soft_link)),
    Case("process unknown filter", "process c.h5", (FORCE, "filter 32004"), crafted(unknown_filter)),
    Case("export scale as text", "export c.h5 --uff e.uff", (FORCE, "'scale'", "expected a number"),
         crafted(attr("scale", "0.001"))),
    Case("export scale missing", "export c.h5 --uff e.uff", (FORCE, "without their 'scale'"),
         crafted(attr("scale", None))),
    Case("export scale NaN", "export c.h5 --uff e.uff", (FORCE, "'scale'", "not a finite number"),
         crafted(attr("scale", float("nan")))),
    Case("process scale per channel wrong", "process c.h5", (FORCE, "'scale' has 2 values"),
         crafted(attr("scale", [1e-3, 2e-3]))),
    Case("process log entries wrong type", "process c.h5", ("/log/entries", "not a run log table"),
         crafted(log_entries_wrong)),
    # NPZ inputs: limits are checked before anything is decompressed or allocated
    Case("identify given a campaign file", "identify any.h5", ("any.h5", "HDF5 campaign file", "labctl process any.h5"),
         lambda folder: h5py.File(folder / "any.h5", "w").close()),
    Case("npz header announcing 73 TiB", "identify huge.npz", ("huge.npz", "'force'", "announces shape"),
         npz_huge_header),
    Case("npz CRC error", "identify crc.npz", ("crc.npz", "damaged"), npz("crc.npz", flip(0.5))),
    Case("npz bad deflate stream", "identify d.npz", ("d.npz", "damaged"),
         npz("d.npz", flip(0.3), compressed=True)),
    Case("npz zip bomb", "identify bomb.npz", ("bomb.npz", "'force'", "zip bomb"),
         npz("bomb.npz", compressed=True, force=np.zeros((1, 2_600_000)))),
    # scripted verdicts that could never apply are refused before the run (they were silently ignored)
    Case("operator review of a missing series", f"{RUN} --operator op.toml", ("op.toml", "series 3", "never apply"),
         _review(series=3)),
    Case("operator review of a missing step", f"{RUN} --operator op.toml", ("op.toml", "step 40", "never apply"),
         _review(step=40)),
    Case("operator review of a missing repetition", f"{RUN} --operator op.toml", ("op.toml", "run 2", "never apply"),
         _review(run=2)),
    Case("operator review of a missing attempt", f"{RUN} --operator op.toml",
         ("op.toml", "attempt 99", "never apply"), _review(attempt=99)),
    # the same campaign given twice would count twice (degrees of freedom 51 -> 105, σ shrinking)
    Case("calibrate the same file twice", "calibrate c.h5 c.h5", ("c.h5", "given twice")),
    Case("calibrate a file and its copy", "calibrate c.h5 copy.h5", ("copy.h5", "same campaign as c.h5"),
         lambda f: shutil.copy(f / "c.h5", f / "copy.h5")),
    Case("calibrate a file and a link to it", "calibrate c.h5 l.h5", ("l.h5", "given twice"), _link("l.h5", "c.h5")),
    # ball campaigns are balls downstream: never rows of a roller stiffness table, never planned as rollers
    Case("process --csv of a ball campaign", "process b.h5 --csv b.csv", ("--csv b.csv", "balls"), _ball_campaign),
    Case("plan from a ball campaign", "plan b.h5", ("b.h5", "series 1 are balls"), _ball_campaign),
    # models refuse loads where the contact is no longer elastic (Tripp went negative at 1e12 N)
    Case("model tripp at 1e12 N", "model tripp --roller-type 1 --load-n 1e12", ("tripp", "1e+12", "validity")),
    Case("model hertz at 1e12 N", "model hertz --ball-diameter-mm 6 --load-n 1e12", ("hertz", "validity")),
    Case("model palmgren at 0 N", "model palmgren --roller-type 1 --load-n 0", ("palmgren", "load 0 N")),
    Case("uff announcing 10^10 points", "identify huge.uff", ("huge.uff", "announces 9999999999 points")
         , uff_huge),
    # world expressions: bounded parse and evaluation, clean errors
    Case("world 400-digit integer", f"{RUN} --world w.toml", ("w.toml", "too large"),
         _world("1" * 400 + " * F")),
    Case("world 1000 nested unary minus", f"{RUN} --world w.toml", ("w.toml", "terms"),
         _world("-" * 1000 + "F")),
    Case("world 5000-term sum", f"{RUN} --world w.toml", ("w.toml", "characters"),
         _world(" + ".join(["F"] * 5000))),
    Case("world 1e300*F", f"{RUN} --world w.toml", ("w.toml", "out of range"), _world("1e300*F")),
    Case("world 1e-300*F", f"{RUN} --world w.toml", ("w.toml", "stiffness of 3.79", "expected 1000"),
         _world("1e-300*F")),
    Case("world table extrapolating to 0", f"{RUN} --world w.toml",
         ("w.toml", "world law 'table'", "expected 1000"),
         _text("w.toml", '[baseline]\nmodel = "table"\n[[baseline.tables]]\nroller_type = 1\n'
                         'load_n = [10, 20]\nstiffness_n_per_m = [1e8, 1e5]\n')),
    Case("devices transverse sensitivity 0.8", f"{RUN} --backend hw --devices d.toml",
         ("d.toml", "transverse_sensitivity", "0.8", "0.5"),
         lambda folder: _devices(folder, "A1Z", "transverse_sensitivity = 0.8")),
    Case("devices cross-axis key on the hammer", f"{RUN} --backend hw --devices d.toml",
         ("d.toml", "mounting_angle_deg"), lambda folder: _devices(folder, "F", "mounting_angle_deg = 2.0")),
    Case("operator review of a step past the plan (plan + 1)", f"{RUN} --operator op.toml",
         ("op.toml", "step 4", "plans 3 load steps", "never apply"), _review(step=4)),
    Case("plan: a table load past the contact models' validity", "plan t.csv",
         ("t.csv", "row 3", "load_n = 1e+06", "(0, 21923] N"), _text("t.csv", BIG_LOAD_TABLE)),
    Case("discrepancy: a table load past the contact models' validity", "discrepancy t.csv",
         ("t.csv", "row 3", "load_n = 1e+06", "(0, 21923] N"), _text("t.csv", BIG_LOAD_TABLE)),
    # a careless export: a thousands separator splits a load into two fields (read before as 1 N and 500 N/m)
    Case("discrepancy: a row with more fields than the header", "discrepancy t.csv",
         ("t.csv", "row 3", "6 fields", "header has 5", "thousands separator"),
         _text("t.csv", f"{TABLE_HEAD}10,10,0.2,100,5e8\n10,10,0.2,1,500,5e8\n10,10,0.2,300,6e8\n")),
    Case("discrepancy: a table separated by semicolons", "discrepancy t.csv", ("t.csv", "';'", "commas"),
         _text("t.csv", TABLE_HEAD.replace(",", ";") + "10;10;0,2;100;5e8\n")),
    Case("discrepancy: a diameter of 1e308 mm", "discrepancy t.csv",
         ("t.csv", "row 2", "diameter_mm", "'1e308'", "(0, 1000] mm"),
         _text("t.csv", f"{TABLE_HEAD}1e308,10,0.2,100,5e8\n10,10,0.2,200,6e8\n")),
    Case("discrepancy: a report folder that cannot be made", "discrepancy t.csv --report /proc/labctl/r",
         ("--report /proc/labctl/r", "cannot make the folder"),
         _text("t.csv", TABLE_HEAD + "".join(f"10,10,0.2,{f},{k}\n" for f, k in
                                             ((100, 5.0e8), (200, 5.6e8), (300, 6.0e8), (400, 6.2e8), (500, 6.5e8))))),
    Case("report: an output folder that cannot be made", "report c.h5 --out /proc/labctl/r",
         ("--out /proc/labctl/r", "cannot make the folder")),
    Case("export: a UFF in a folder that cannot be written", "export c.h5 --uff /proc/labctl/a.uff",
         ("/proc/labctl/a.uff", "cannot write here")),
    Case("simulate impacts: a rail Ra of 1e9 µm", "simulate impacts --roller-type 1 --load-n 440 --rail-ra-um 1e9 "
         "--out i.npz", ("--rail-ra-um", "(0, 50] µm")),
    Case("import: a rail Ra of 1e9 µm", "import x.uff --manifest m.csv --out i.h5 --rail-ra-um 1e9",
         ("--rail-ra-um", "[0, 50] µm"), _text("m.csv", "load_n,repetition\n440,1\n")),
    Case("demo: an output folder that cannot be made", "demo --out /proc/labctl/d",
         ("--out /proc/labctl/d", "cannot make the folder")),
    Case("programme: an output folder that cannot be made", "programme --out /proc/labctl/p quick_check",
         ("--out /proc/labctl/p", "cannot make the folder")),
    Case("discrepancy: a rail Ra of 1e300 µm", "discrepancy t.csv",
         ("t.csv", "row 2", "rail_ra_um", "[0, 50] µm"), _text("t.csv", f"{TABLE_HEAD}10,10,1e300,100,5e8\n")),
]


def _devices(folder: Path, channel: str, line: str) -> None:
    """The example devices file with ``line`` added to channel ``channel``'s table."""
    from labctl.data import data_path

    text = data_path("devices.example.toml").read_text(encoding="utf-8")
    head = f'name = "{channel}"'
    at = text.index(head)
    (folder / "d.toml").write_text(text[:at] + line + "\n" + text[at:], encoding="utf-8")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from labctl.campaign import run_campaign

    path = tmp_path_factory.mktemp("bad") / "c.h5"
    assert run_campaign("quick_check", out=path, backend="sim", seed=3).status == "complete"
    return path


def _digests(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()
            if p.is_file() and not p.is_symlink()}


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_bad_input_is_one_line_and_changes_nothing(case: Case, campaign: Path, tmp_path: Path, capsys,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    shutil.copy(campaign, tmp_path / "c.h5")
    if case.make is not None:
        case.make(tmp_path)
    monkeypatch.chdir(tmp_path)
    before = _digests(tmp_path)
    proc = labctl_here(capsys, *case.argv.split())
    assert_one_line_error(proc, *case.fragments)
    after = _digests(tmp_path)
    assert {name: after.get(name) for name in before} == before  # no file that was there changed
    assert not [n for n in after if n not in before and n.startswith(".")]  # no temporary file left behind
    assert after.keys() == before.keys()  # no output appeared (a refused run makes no campaign file)
