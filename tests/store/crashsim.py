"""Build the disk images a crash could leave, from a RecordingFileSystem's operation log.

The model: a file's data is durable up to its last fsync; later writes may each be lost,
land whole, land torn at a 512-byte sector boundary, land as zeros (the size grew but the
data did not), or land as garbage, and in any order (a later write may land while an
earlier one does not). Directory entries (create, rename, unlink) are durable after an
fsync of the directory; before it, a prefix of them has happened.
"""

from __future__ import annotations

import os
import random
from dataclasses import dataclass, field

SECTOR = 512
MODES = ("lost", "all", "prefix", "torn", "zero", "garbage", "reorder")


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

    def _dir_after_crash(self, rng: random.Random) -> dict[str, int]:
        names = dict(self.durable_names)
        for op in self.pending_dir[: rng.randint(0, len(self.pending_dir))]:
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
            elif mode == "zero":
                _apply(buf, ("write", off, b"\0" * len(data)))
            elif mode == "garbage":
                _apply(buf, ("write", off, rng.randbytes(len(data))))
        return bytes(buf)

    def image(self, rng: random.Random, mode: str) -> dict[str, bytes]:
        return {
            name: self._content_after_crash(self.inodes[ino], rng, mode)
            for name, ino in self._dir_after_crash(rng).items()
        }
