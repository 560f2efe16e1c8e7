"""Reads of segment tails and side files are bounded (issue 16 item 3, FORMAT.md "Bounded reads").

A small sparse file can claim gigabytes: recovery, readers, fsck and repair once read a
whole tail (or side file) into memory to look for records in it, so a 4 GiB zero tail cost
8 GiB. Each case runs in a fresh process and measures its peak RSS (VmHWM) around
the one operation.
"""

import json
import os
import re
import subprocess
import sys
import textwrap

import pytest

import cclogfs
from cclogfs.store.format import SEGMENT_HEADER_SIZE

# What FORMAT.md states a tail search may hold: one search chunk, one read buffer and one
# record. The records here are small; the bound checked is generous for the interpreter.
PEAK_LIMIT_MIB = 64

RUN = textwrap.dedent("""
    import json, sys
    from cclogfs.store import open_store
    from cclogfs.store.fsck import check_store
    from cclogfs.store.repair import repair_store

    def rss():
        # VmHWM, not ru_maxrss: a child's ru_maxrss starts at its parent's peak (the test
        # worker's), which would hide any growth here; VmHWM is this address space's own.
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmHWM:")) // 1024

    path, what = sys.argv[1], sys.argv[2]
    before = rss()
    if what == "reader":
        with open_store(path, readonly=True) as s:
            out = [str(p) for p in s.recovery.problems]
    elif what == "writer":
        with open_store(path) as s:
            out = [str(p) for p in s.recovery.problems]
    elif what == "fsck":
        out = [str(f) for f in check_store(path, deep=True).findings]
    else:
        out = repair_store(path).actions
    print(json.dumps({"peak_mib": rss() - before, "out": out}))
""")


def peak(path, what):
    """Peak RSS growth (MiB) of one operation on the store at `path`, in a fresh process."""
    done = subprocess.run([sys.executable, "-c", RUN, str(path), what], capture_output=True, text=True,
                          timeout=120)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


KILLED = textwrap.dedent("""
    import json, os, sys
    import cclogfs
    writer = cclogfs.open_store(sys.argv[1], create=True, sync_every_ms=None, sync_every_bytes=None)
    for i in range(int(sys.argv[2])):
        writer.put_window("/a", [(i, json.dumps({"x": i}))])
        if i == 0:
            writer.sync()  # later records are past the synced point: a torn tail, not damage
    writer.active.flush()
    print(writer.active.path)
    os._exit(0)  # killed: no sync, no clean close
""")


def recording(path, n=3):
    """The store a writer killed mid-recording leaves: the active segment's path."""
    done = subprocess.run([sys.executable, "-c", KILLED, str(path), str(n)], capture_output=True, text=True,
                          check=True)  # fmt: skip
    return done.stdout.strip()


def sparse_tail(seg, size, tail=b""):
    """Extend segment `seg` to `size` bytes with a hole, then `tail` at its end."""
    with open(seg, "r+b") as f:
        f.truncate(size - len(tail))
        f.seek(size - len(tail))
        f.write(tail)


def test_a_4_gib_sparse_zero_tail_costs_no_memory(tmp_path):
    seg = recording(tmp_path / "s")
    end = os.path.getsize(seg)
    sparse_tail(seg, 4 << 30)
    for what in ("reader", "fsck", "writer"):
        got = peak(tmp_path / "s", what)
        assert got["peak_mib"] < PEAK_LIMIT_MIB, (what, got)
        assert re.search(rf"(at offset |@){end}: zero fill", " ".join(got["out"])), (what, got)
    assert os.path.getsize(seg) == end  # the writer cut the zero tail, and only that
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [w.seq for w in store.query()] == [0, 1, 2]


def test_a_damaged_record_before_a_2_gib_sparse_tail_costs_no_memory(tmp_path):
    # Damage, a hole, then an intact record at the very end: the tail must be searched
    # (the record past the damage is evidence) and copied to a side file, both streamed.
    seg = recording(tmp_path / "s", n=4)
    data = open(seg, "rb").read()
    last = data.rfind(b"CCLR")
    record = data[last:]
    with open(seg, "r+b") as f:
        f.seek(last + 5)
        f.write(b"\xff")  # the last record's header: damaged
    sparse_tail(seg, 2 << 30, record)
    for what in ("reader", "fsck"):
        got = peak(tmp_path / "s", what)
        assert got["peak_mib"] < PEAK_LIMIT_MIB, (what, got)
        assert re.search("1 intact records (among them|after it)", " ".join(got["out"])), (what, got)
    got = peak(tmp_path / "s", "writer")
    assert got["peak_mib"] < PEAK_LIMIT_MIB, got
    side = [n for n in os.listdir(tmp_path / "s") if ".seg.tail-" in n]
    assert side == [f"{os.path.basename(seg)}.tail-{last}"]
    side_path = tmp_path / "s" / side[0]
    assert os.path.getsize(side_path) == (2 << 30) - last
    assert os.stat(side_path).st_blocks * 512 < 16 << 20  # the hole stayed a hole (one chunk was read)
    for what in ("fsck", "repair"):
        got = peak(tmp_path / "s", what)
        assert got["peak_mib"] < PEAK_LIMIT_MIB, (what, got)
    assert "salvaged 1 intact records" in " ".join(got["out"])


def test_a_large_side_file_is_searched_in_bounded_memory(tmp_path):
    # Not sparse: every byte must be read, a chunk at a time.
    seg = recording(tmp_path / "s", n=2)
    data = open(seg, "rb").read()
    record = data[data.rfind(b"CCLR"):]
    name = f"{os.path.basename(seg)}.tail-{len(data)}"
    with open(tmp_path / "s" / name, "wb") as f:
        for _ in range(256):
            f.write(b"garbage!" * (1 << 17))  # 1 MiB
        f.write(record)
    assert os.path.getsize(tmp_path / "s" / name) > 256 << 20
    got = peak(tmp_path / "s", "fsck")
    assert got["peak_mib"] < PEAK_LIMIT_MIB, got
    assert f"{name}: bytes recovery cut from the log hold 1 intact records" in " ".join(got["out"])
    got = peak(tmp_path / "s", "repair")
    assert got["peak_mib"] < PEAK_LIMIT_MIB, got
    assert f"salvaged 1 intact records of {name}" in " ".join(got["out"])


@pytest.mark.parametrize("size", [SEGMENT_HEADER_SIZE + 10, 1 << 30])
def test_a_tail_segment_with_a_damaged_header_and_a_sparse_body(tmp_path, size):
    # Whether a segment with a damaged header holds records is a streamed search too.
    seg = recording(tmp_path / "s", n=1)
    with cclogfs.open_store(tmp_path / "s", sync_every_ms=None, segment_records=1) as store:
        store.put_window("/a", [(9, "{}")])  # seals, and starts the next segment
        nxt = store.active.path
    with open(nxt, "r+b") as f:
        f.write(b"\0" * SEGMENT_HEADER_SIZE)
    sparse_tail(nxt, size)
    got = peak(tmp_path / "s", "reader")
    assert got["peak_mib"] < PEAK_LIMIT_MIB, got
    assert "bad segment header" in " ".join(got["out"]), (seg, got)
