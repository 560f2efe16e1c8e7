"""Build the disk images a crash could leave, from a RecordingFileSystem's operation log.

The model: a file's data is durable up to its last fsync; later writes may each be lost,
land whole, land torn at a 512-byte sector boundary, land as zeros (the size grew but the
data did not), or land as garbage, and in any order (a later write may land while an
earlier one does not). Directory entries (create, rename, unlink) are durable after an
fsync of the directory; before it, a prefix of them has happened, or (`reorder_dir`, as
ALICE explores) any subset that keeps the order of the operations on each name. Each file
may fail in its own mode (`image_mixed`). A failed fsync loses the pages it was writing
for good: a later fsync does not write them, only a new write of the whole range does.
"""

from __future__ import annotations

import os
import random
from dataclasses import dataclass, field

SECTOR = 512
# "reorder": any subset of the pending writes lands; "hole": all but the first (the worst
# reordering, so that every boundary checks it, not only the lucky draws of "reorder").
MODES = ("lost", "all", "prefix", "torn", "zero", "garbage", "reorder", "hole")


@dataclass
class Inode:
    durable: bytearray = field(default_factory=bytearray)
    current: bytearray = field(default_factory=bytearray)
    pending: list[tuple] = field(default_factory=list)  # ("write", off, data) | ("truncate", size)
    # Ranges a failed fsync left marked clean but never written ("fsyncgate"): a later
    # fsync does not write them; only a new write of the whole range does.
    lost: list[tuple[int, int]] = field(default_factory=list)


def _apply(buf: bytearray, op: tuple) -> None:
    if op[0] == "truncate":
        del buf[op[1] :]
        buf.extend(b"\0" * (op[1] - len(buf)))
        return
    _, off, data = op
    if len(buf) < off + len(data):
        buf.extend(b"\0" * (off + len(data) - len(buf)))
    buf[off : off + len(data)] = data


class DiskModel:
    """Replays operations; `image(rng, mode)` is one possible state after a crash now."""

    def __init__(self) -> None:
        self.inodes: list[Inode] = []
        self.names: dict[str, int] = {}  # what a process sees now
        self.durable_names: dict[str, int] = {}
        self.pending_dir: list[tuple] = []

    def apply(self, op: tuple) -> None:
        kind = op[0]
        name = os.path.basename(op[1]) if len(op) > 1 and isinstance(op[1], str) else None
        if kind == "create":
            self.inodes.append(Inode())
            self.names[name] = len(self.inodes) - 1
            self.pending_dir.append(("link", name, len(self.inodes) - 1))
        elif kind in ("write", "truncate") and name in self.names:
            inode = self.inodes[self.names[name]]
            pop = ("write", op[2], op[3]) if kind == "write" else ("truncate", op[2])
            _apply(inode.current, pop)
            inode.pending.append(pop)
            if kind == "write":
                end = op[2] + len(op[3])
                inode.lost = [(a, b) for a, b in inode.lost if not (op[2] <= a and b <= end)]
        elif kind == "fsync" and name in self.names:
            inode = self.inodes[self.names[name]]
            durable = bytearray(inode.current)
            for a, b in inode.lost:
                if a < len(durable):
                    old = bytes(inode.durable[a:b]).ljust(b - a, b"\0")
                    durable[a : min(b, len(durable))] = old[: min(b, len(durable)) - a]
            inode.durable = durable
            inode.pending.clear()
        elif kind == "fsync_failed" and name in self.names:
            inode = self.inodes[self.names[name]]
            inode.lost += [(op[1], op[1] + len(op[2])) for op in inode.pending if op[0] == "write"]
            inode.pending.clear()
        elif kind == "rename" and name not in self.names:
            # A directory renamed (a store created in a hidden sibling, then moved into place):
            # the model's namespace is flat, so the files it holds are already in it.
            pass
        elif kind == "rename":
            dst = os.path.basename(op[2])
            self.names[dst] = self.names.pop(name)
            self.pending_dir.append(("rename", name, dst))
        elif kind == "unlink":
            self.names.pop(name, None)
            self.pending_dir.append(("unlink", name))
        elif kind == "fsync_dir":
            self.durable_names = dict(self.names)
            self.pending_dir.clear()

    def seed(self, files: dict[str, bytes]) -> None:
        """Start from a disk that durably holds `files` (a crash image, to crash again)."""
        for name, data in files.items():
            self.inodes.append(Inode(bytearray(data), bytearray(data)))
            self.names[name] = self.durable_names[name] = len(self.inodes) - 1

    def _reordered_dir_ops(self, rng: random.Random) -> list[tuple]:
        """Any subset of the pending directory operations that keeps the order of those on
        one name (a rename reaches the disk only after the create of what it renames)."""
        chosen, blocked = [], set()
        for op in self.pending_dir:
            names = {op[1], op[2]} if op[0] == "rename" else {op[1]}
            if names & blocked or rng.random() < 0.5:
                blocked |= names
            else:
                chosen.append(op)
        return chosen

    def _dir_after_crash(self, rng: random.Random, reorder: bool = False) -> dict[str, int]:
        names = dict(self.durable_names)
        ops = self._reordered_dir_ops(rng) if reorder else self.pending_dir[: rng.randint(0, len(self.pending_dir))]
        for op in ops:
            if op[0] == "link":
                names[op[1]] = op[2]
            elif op[0] == "rename":
                if op[1] in names:
                    names[op[2]] = names.pop(op[1])
            else:
                names.pop(op[1], None)
        return names

    def _content_after_crash(self, inode: Inode, rng: random.Random, mode: str) -> bytes:
        buf = bytearray(inode.durable)
        ops = inode.pending
        if not ops or mode == "lost":
            return bytes(buf)
        if mode == "all":
            chosen = ops
        elif mode == "reorder":
            chosen = [op for op in ops if rng.random() < 0.5]
        elif mode == "hole":
            chosen = ops[1:]
        else:
            chosen = ops[: rng.randint(0, len(ops) - 1)]
        for op in chosen:
            _apply(buf, op)
        nxt = ops[len(chosen)] if mode in ("torn", "zero", "garbage", "prefix") and len(chosen) < len(ops) else None
        if nxt is not None and nxt[0] == "write":
            _, off, data = nxt
            if mode == "torn":
                cuts = [c for c in range(off - off % SECTOR + SECTOR, off + len(data), SECTOR)]
                if cuts:
                    _apply(buf, ("write", off, data[: rng.choice(cuts) - off]))
            elif mode in ("zero", "garbage"):
                # Only what the write appended can come back as zeros (the size grew, the data
                # did not) or garbage; bytes it overwrote in place hold the old or new sector.
                keep = max(0, min(len(data), len(buf) - off))
                tail = len(data) - keep
                _apply(buf, ("write", off, data[:keep] + (b"\0" * tail if mode == "zero" else rng.randbytes(tail))))
        return bytes(buf)

    def image(self, rng: random.Random, mode: str) -> dict[str, bytes]:
        return {
            name: self._content_after_crash(self.inodes[ino], rng, mode)
            for name, ino in self._dir_after_crash(rng).items()
        }

    def image_mixed(self, rng: random.Random, modes: tuple[str, ...] = MODES) -> dict[str, bytes]:
        """A crash image where each file fails in its own mode, and directory operations
        not yet fsynced land in any order that keeps each name's."""
        return {
            name: self._content_after_crash(self.inodes[ino], rng, rng.choice(modes))
            for name, ino in self._dir_after_crash(rng, reorder=True).items()
        }

    def pending(self) -> bool:
        """Whether anything is not durable yet (else every image is the same)."""
        return bool(self.pending_dir) or any(self.inodes[i].pending for i in self.names.values())
