"""The messages of an indexed MCAP file chunk by chunk, so that one damaged chunk is named.

rosbags' MCAP reader merges its chunks' messages in log-time order from the summary's
chunk indexes; a chunk whose bytes fail (checksum, decompression) ended the whole file with
"Chunk checksum mismatch." and no offset, and a chunk index that points at other bytes (a
chunk cut out of the file) went unnoticed: its messages were left out with exit 0. Here
each chunk is read as rosbags reads it (`msgsrc`), then checked against the summary: a
chunk record where the index says, as long, holding as many messages per channel as the
index counts. A chunk that fails goes to `bad(chunk, why)`, which raises (stop) or counts
it and goes on (`--on-error skip`).

A chunk without message indexes (a writer may leave them out: the `mcap` Writer without
IndexType.MESSAGE) has an empty channel count in rosbags' chunk index, and rosbags skipped
it as holding none of the selected channels: every message in it was left out with exit 0
(3,996 of 8,197 read from a file whose later chunks had none). Such a chunk is read whole,
as rosbags reads any chunk; its count cannot be checked, as no index counts it.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Collection, Iterator
from typing import Any

from rosbags.rosbag2.storage_mcap import McapReader, msgsrc

from .mcapbad import not_a_chunk


def is_indexed_mcap(reader: Any) -> McapReader | None:
    """The MCAP storage of a rosbags reader of one indexed MCAP file, else None."""
    storage = getattr(reader, "storage", None)
    return storage if isinstance(storage, McapReader) and storage.chunks else None


def expected(chunk: Any, channels: Collection[int]) -> int:
    """Messages of `channels` the summary's index counts in `chunk`."""
    return sum(chunk.channel_count.get(cid, 0) for cid in channels)


def unindexed(chunk: Any) -> bool:
    """Whether `chunk` has no message indexes: which channels it holds is unknown until read."""
    return not chunk.message_index_offsets


def messages(storage: McapReader, connections: Collection[Any],
             bad: Callable[[Any, str], None]) -> Iterator[tuple[Any, int, bytes]]:  # fmt: skip
    """(connection, log time, bytes) of `connections`, in log-time order, as rosbags'
    `McapReader.messages` gives them, but a chunk that cannot be read goes to `bad`."""
    cmap = {c.id: c for c in connections}
    chunks = [c for c in storage.chunks if unindexed(c) or expected(c, cmap)]
    merged = heapq.merge(*(_chunk(storage, c, cmap, bad) for c in chunks))
    for stamp, offset, connection, data in merged:
        if offset:  # each chunk's first item is its start time alone (how rosbags merges)
            yield connection, stamp, data


def _chunk(storage: McapReader, chunk: Any, cmap: dict[int, Any], bad: Callable[[Any, str], None]) -> Iterator[Any]:
    items = msgsrc(chunk, cmap, chunk.message_start_time, chunk.message_end_time + 1, storage.bio)
    yield next(items)  # the start time: nothing read yet, so the merge reads chunks in time order
    why = not_a_chunk(storage.bio, chunk)
    if why is None:
        try:
            found = list(items)  # msgsrc has decompressed and sorted the chunk whole already
        except Exception as err:  # rosbags raises ReaderError, zstd/lz4 errors, struct.error
            why = str(err) or type(err).__name__
        else:
            if unindexed(chunk) or len(found) == expected(chunk, cmap):
                yield from found
                return
            why = f"it holds {len(found):,} of the {expected(chunk, cmap):,} messages its index counts"
    bad(chunk, why)
