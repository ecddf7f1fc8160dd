"""The store's blobs: plans and scenario documents kept as zlib-compressed JSON, and read back
no larger than :data:`MAX_BLOB_BYTES` (a submitted store is hostile data)."""

from __future__ import annotations

import zlib
from typing import overload

from ...errors import StoreError


#: The most a stored plan or scenario document may inflate to: twice the plan-size rule (64 MB
#: of JSON; a closed loop's joined plan is a little larger than its steps' messages) and three
#: times the largest scenario document (4,000,000 cells as base64, 43 MB).
MAX_BLOB_BYTES = 128 * 2**20


class BlobTooLargeError(StoreError, ValueError):
    """A stored blob that inflates past :data:`MAX_BLOB_BYTES`."""


def compress(text: str) -> bytes:
    return zlib.compress(text.encode(), 6)


@overload
def decompress(blob: bytes) -> str: ...
@overload
def decompress(blob: None) -> None: ...
def decompress(blob: bytes | None) -> str | None:
    """The text of a ``plan`` or ``scenarios`` blob as stored (zlib-compressed JSON), or None.

    A blob that inflates past :data:`MAX_BLOB_BYTES` is refused (:class:`BlobTooLargeError`)
    after inflating at most that much: a submitted store is hostile data, and a megabyte of
    zeros compressed can claim a gigabyte of memory.
    """
    if blob is None:
        return None
    inflate = zlib.decompressobj()
    text = inflate.decompress(blob, MAX_BLOB_BYTES + 1)
    if len(text) > MAX_BLOB_BYTES or inflate.unconsumed_tail:
        raise BlobTooLargeError(f"a stored blob of {len(blob):,} bytes inflates to more than {MAX_BLOB_BYTES / 2**20:.0f} MB "
                                "(no plan or scenario is that large: a decompression bomb?); it was not read")
    return text.decode()
