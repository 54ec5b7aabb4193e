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

import pytest

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


def _link(name: str, target: str) -> Callable[[Path], None]:
    return lambda folder: (folder / name).symlink_to(target)


def _hard_link(name: str, target: str) -> Callable[[Path], None]:
    return lambda folder: (folder / name).hardlink_to(folder / target)


def _text(name: str, text: str) -> Callable[[Path], None]:
    return lambda folder: (folder / name).write_text(text, encoding="utf-8")


def _catalogue(folder: Path) -> None:
    from labctl.archive import index

    index(folder / "arc.db", [folder / "c.h5"])


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
    Case("archive index text file as db", "archive index c.h5 --db notes.db", ("--db notes.db", "not an SQLite"),
         _text("notes.db", "shopping list\n")),
]


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
    assert _digests(tmp_path) == before  # no file changed, none added (no half-written output left behind)
