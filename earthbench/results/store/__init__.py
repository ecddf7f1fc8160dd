"""The results store (docs/DESIGN.md §8): :class:`Store` (:mod:`.database`: one SQLite file, one row
per run, named methods for every read and write), its schema and the steps that bring an older
store up to date (:mod:`.schema`), and the readers that turn stored runs into frames for
analysis (:mod:`.frames`: :func:`load_runs`, :func:`suite_members`). Every SQL statement of
earthbench is in this package."""

from __future__ import annotations

from .blobs import MAX_BLOB_BYTES, BlobTooLargeError, decompress
from .database import (
    DEFAULT_DB,
    LOAD_COLUMNS,
    METRIC_COLUMNS,
    Store,
    SuiteRecord,
    default_db,
    sealed_origin,
)
from .frames import check_one_rules, load_runs, rules_versions, stored_steps, suite_members
from .schema import APPLICATION_ID, MIGRATIONS, SCHEMA_VERSION

__all__ = [
    "APPLICATION_ID", "DEFAULT_DB", "LOAD_COLUMNS", "MAX_BLOB_BYTES", "METRIC_COLUMNS", "MIGRATIONS", "SCHEMA_VERSION",
    "BlobTooLargeError", "Store", "SuiteRecord", "check_one_rules", "decompress", "default_db", "load_runs", "rules_versions",
    "sealed_origin", "stored_steps", "suite_members",
]
