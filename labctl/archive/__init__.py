"""A lab's whole archive of campaign files: catalogue them, query the catalogue, reprocess many at once.

``index(db, folders)`` brings an SQLite catalogue up to date; ``query(db, where)`` reads it (read-only);
``stiffness_points(rows)`` turns a query's rows into a stiffness table; ``process_files(paths, workers=N)``
reprocesses campaigns in parallel with Dask and writes each one's results beside it (docs/archive.md).
"""

from __future__ import annotations

from labctl.archive.catalogue import IndexReport, campaign_files, index
from labctl.archive.query import QueryResult, query, read_only_connection, stiffness_points
from labctl.archive.runner import FileOutcome, process_files, reprocess_file

__all__ = ["FileOutcome", "IndexReport", "QueryResult", "campaign_files", "index", "process_files", "query",
           "read_only_connection", "reprocess_file", "stiffness_points"]
