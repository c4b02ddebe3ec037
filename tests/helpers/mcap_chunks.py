"""What a sequence MCAP's summary says of its chunks."""

from __future__ import annotations

from pathlib import Path


def chunk_compressions(path: Path) -> set[str]:
    """The compression named by every chunk of the MCAP at ``path`` ("" for none)."""
    from mcap.reader import make_reader

    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    return {ci.compression for ci in summary.chunk_indexes}
