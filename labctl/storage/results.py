"""Reprocessed results kept beside a campaign file: ``NAME.h5`` → ``NAME.h5.results.json`` (docs/archive.md).

The campaign file is only ever read, so reprocessing cannot damage the raw impacts, works on archives whose
campaign files are write-protected, and many processes can reprocess different files at once. The sidecar is
written atomically (a temporary file renamed over it) and idempotently: a document equal to the stored one
apart from ``processed_utc`` leaves the file untouched.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from labctl.errors import InputError
from labctl.storage.records import jsonable
from labctl.storage.writer import utc_now

RESULTS_FORMAT = "labctl-results"
RESULTS_FORMAT_VERSION = 1
SUFFIX = ".results.json"
WHEN = "processed_utc"


def results_path(campaign: str | Path) -> Path:
    """Where the reprocessed results of a campaign file live."""
    p = Path(campaign)
    return p.with_name(p.name + SUFFIX)


def attrs_sha256(attrs: Mapping[str, Any]) -> str:
    """A content hash of a campaign's root attributes (identifies a campaign whatever its path or mtime)."""
    text = json.dumps(jsonable(dict(attrs)), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def read_results(campaign: str | Path) -> dict[str, Any] | None:
    """The stored results document of a campaign (None when it has none); a malformed one is an InputError."""
    p = results_path(campaign)
    if not p.is_file():
        return None
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{p}: not a readable results file ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != RESULTS_FORMAT:
        raise InputError(f"{p}: not a labctl results file (no format '{RESULTS_FORMAT}')")
    return doc


def write_results(campaign: str | Path, payload: Mapping[str, Any]) -> bool:
    """Store ``payload`` beside the campaign; True when the file was (re)written, False when it already held it."""
    doc = {"format": RESULTS_FORMAT, "format_version": RESULTS_FORMAT_VERSION, **jsonable(dict(payload))}
    doc.pop(WHEN, None)
    p = results_path(campaign)
    try:
        old = read_results(campaign)
    except InputError:
        old = None
    if old is not None and {k: v for k, v in old.items() if k != WHEN} == doc:
        return False
    doc[WHEN] = utc_now()
    text = json.dumps(doc, indent=1, sort_keys=True, allow_nan=False) + "\n"
    fd, tmp = tempfile.mkstemp(prefix=p.name + ".", suffix=".tmp", dir=p.parent)
    try:
        os.chmod(tmp, 0o644)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return True
