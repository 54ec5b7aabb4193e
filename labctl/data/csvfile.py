"""Reading a small CSV file as (line number, record) pairs with errors that name the file and the problem."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

from labctl.errors import InputError


def read_csv_records(path: str | Path, *, what: str, required: Sequence[str], allowed: Sequence[str] | None = None,
                     layout: str = "") -> list[tuple[int, dict[str, str]]]:
    """Records keyed by stripped header names, blank rows skipped; missing or unknown columns are refused.

    ``what`` names the kind of file in messages (``stiffness-table CSV``, ``manifest``); ``layout`` says which
    columns such a file has.
    """
    p = Path(path)
    note = f"; {layout}" if layout else f" (required: {', '.join(required)})"
    try:
        with p.open(newline="", encoding="utf-8-sig") as fh:
            reader = csv.DictReader(fh)
            header = [h.strip() for h in (reader.fieldnames or [])]
            missing = [c for c in required if c not in header]
            if missing and len(header) == 1 and ";" in header[0]:
                raise InputError(f"{p}: the header is separated by ';', expected commas (save it as comma-separated "
                                 "CSV, with '.' as the decimal point)")
            if missing:
                raise InputError(f"{p}: missing column(s) {', '.join(missing)}{note}")
            unknown = [h for h in header if h and allowed is not None and h not in allowed]
            if unknown:
                raise InputError(f"{p}: unknown column(s) {', '.join(unknown)}; expected among {', '.join(allowed)}")
            reader.fieldnames = header
            records = []
            for rec in reader:
                extra = rec.pop(None, None)  # fields past the header's last column
                if extra and any(v.strip() for v in extra):
                    raise InputError(f"{p}: row {reader.line_num}: {len(header) + len(extra)} fields, the header has "
                                     f"{len(header)} (a comma inside a value, such as a thousands separator? quote "
                                     "the value or drop the separator)")
                if any((v or "").strip() for v in rec.values() if isinstance(v, str)):
                    records.append((reader.line_num, rec))
            return records
    except FileNotFoundError:
        raise InputError(f"{p}: file not found (expected a {what})") from None
    except IsADirectoryError:
        raise InputError(f"{p}: is a directory, expected a {what}") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{p}: not a readable CSV file ({exc})") from None
