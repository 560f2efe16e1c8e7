"""An MCAP chunk that cannot be read, as the ROS (`mcapchunks`) and JSON (`mcapjson`)
readers both say it: named by file and byte offset, with its messages and times; the
error (`--on-error stop`), or skipped and listed in `lost` (`--on-error skip`, exit 4).

Only the standard library here: the JSON reader must not import rosbags (slow to import).
"""

from __future__ import annotations

from typing import Any, BinaryIO

from ..errors import SourceError

_CHUNK_OP = 0x06


def not_a_chunk(bio: BinaryIO, chunk: Any) -> str | None:
    """Why the bytes where the summary's index puts `chunk` (rosbags' or mcap's chunk
    index: both name chunk_start_offset and chunk_length) are not its chunk record (None: they are)."""
    bio.seek(chunk.chunk_start_offset)
    head = bio.read(9)
    if len(head) < 9:
        return "the file ends before it"
    length = int.from_bytes(head[1:], "little")
    if head[0] != _CHUNK_OP or length + 9 != chunk.chunk_length:
        return ("the bytes there are not the chunk record the summary's index describes (bytes cut out of "
                "or moved in the file)")  # fmt: skip
    return None


def channel_counts(chunk: Any) -> dict[int, int]:
    """Messages per channel in `chunk` (mcap's chunk index), from the lengths of its message
    index records, as rosbags counts them: each is 15 bytes of header (opcode, length,
    channel id, array length) and 16 per message. Empty when the chunk has no message index."""
    starts = sorted((offset, cid) for cid, offset in chunk.message_index_offsets.items())
    ends = [offset for offset, _ in starts[1:]] + [chunk.chunk_start_offset + chunk.chunk_length + chunk.message_index_length]
    return {cid: (end - offset - 15) // 16 for (offset, cid), end in zip(starts, ends)}


class BadChunks:
    """The chunks of one file that could not be read."""

    def __init__(self, name: str, on_error: str) -> None:
        self.name = name
        self.on_error = on_error
        self.said: list[str] = []

    def __call__(self, chunk: Any, why: str, count: int | None) -> None:
        """`chunk` cannot be read for `why`; `count`: its messages of the selection (None:
        not known, as it has no message index)."""
        what = f"{count:,} messages" if count is not None else "messages not counted, as it has no message index,"
        said = (f"the chunk at byte {chunk.chunk_start_offset:,} ({what} logged {chunk.message_start_time} "
                f"to {chunk.message_end_time} ns) cannot be read: {why}")  # fmt: skip
        if self.on_error == "stop":
            raise SourceError(f"{self.name}: {said}; the messages before it were read. Record with --on-error skip "
                              "to keep the other chunks (it says what was lost and exits 4).")  # fmt: skip
        self.said.append(said)

    @property
    def lost(self) -> str | None:
        """What was lost (chunks skipped), None when nothing was."""
        if not self.said:
            return None
        return (f"{self.name} is damaged: {len(self.said):,} chunks could not be read and were skipped "
                f"(--on-error skip), their messages not recorded: {'; '.join(self.said)}")  # fmt: skip
