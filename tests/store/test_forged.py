"""Issue 16 items 3-5: files whose checksums hold but whose content is forged or absurd
(MANIFEST, .idx, record meta and config), sparse files far over their format's size, and
entries that are not files. Each must give a one-line project error naming the file and
field, a non-zero exit, no traceback, bounded memory, and change nothing stored."""

import json
import struct
import subprocess
import sys
from pathlib import Path

import pytest

import cclogfs
from cclogfs.cli import main
from cclogfs.errors import CclogError, CorruptionError, InvalidInputError, StoreError
from cclogfs.store import check_store, repair_store
from cclogfs.store.format import (
    INDEX_HEADER,
    INDEX_MAGIC,
    MANIFEST,
    MANIFEST_HEADER,
    MANIFEST_MAGIC,
    crc32c,
    pack_manifest,
    pack_record,
    unpack_manifest,
    xxh3,
)
from cclogfs.store import index as index_mod
from cclogfs.store.format import INDEX_ENTRY
from cclogfs.store.index import SegmentIndex
from cclogfs.upkeep.policy import Policy, parse_rule

GiB = 1 << 30


def _store(path, n=10):
    with cclogfs.open_store(path, create=True, segment_records=4, codec="zstd", sync_every_ms=None) as s:
        for i in range(n):
            s.put_window("/odom", [(i * 10 + k, json.dumps({"x": k})) for k in range(3)], meta={"i": i})
    return path


def _files(path):
    return {p.name: p.read_bytes() for p in sorted(Path(path).iterdir()) if p.is_file()}


def _body(path):
    return unpack_manifest((path / MANIFEST).read_bytes())


def _write_manifest(path, body):
    (path / MANIFEST).write_bytes(pack_manifest(body) if isinstance(body, dict) else _frame(body))


def _frame(text: bytes) -> bytes:
    head = MANIFEST_HEADER.pack(MANIFEST_MAGIC, 1, 0, len(text)) + text
    return head + struct.pack("<I", crc32c(head))


def _refused_everywhere(path, capsys, *words):
    """Writer and reader refuse with one line naming MANIFEST and `words`; cat, info, fsck
    exit non-zero without a traceback; no file changed."""
    before = _files(path)
    for readonly in (False, True):
        with pytest.raises(CorruptionError) as err:
            cclogfs.open_store(path, readonly=readonly)
        msg = str(err.value)
        assert "\n" not in msg and MANIFEST in msg and all(w in msg for w in words), msg
    for cmd in (["cat"], ["info"], ["fsck"], ["fsck", "--deep"]):
        assert main([*cmd, str(path)]) != 0
    out = capsys.readouterr()
    assert "Traceback" not in out.err + out.out
    assert _files(path) == before


# -- item 4 and 5: MANIFEST bodies ------------------------------------------------------


@pytest.mark.parametrize("text, words", [
    (b"{", ["not JSON"]),
    (b"[" * 100_000, ["not JSON"]),
    (b"[]", ["body"]),
    (json.dumps({"format_version": 3}).encode(), ["store_id"]),
    (json.dumps({"format_version": "3"}).encode(), ["format_version"]),
    (b'{"format_version": 3, "n": 1' + b"0" * 5000 + b"}", ["not JSON"]),
])  # fmt: skip
def test_a_manifest_body_that_is_not_one_is_refused(tmp_path, capsys, text, words):
    path = _store(tmp_path / "s")
    _write_manifest(path, text)
    _refused_everywhere(path, capsys, *words)


@pytest.mark.parametrize("field, value", [
    ("segments.-1.end_seq", 2**64 + 4),
    ("segments.-1.size", "x"),
    ("segments.-1.streams", []),
    ("segments.-1.streams./odom.start_ns", 2**70),
    ("segments.0.gen", True),
    ("segments.-1.first_seq", 5),
    ("segments.0.damaged", [{"offset": 1}]),
    ("generation", -1),
    ("checkpoint", {"first_seq": 8}),
    ("first_seq", 2**70),
    ("first_seq", 1000),
    ("quarantine", ["../../victim"]),
    ("dropped", {"segments": 0, "streams": {"/a": {}}}),
    ("segments", {"0": 1}),
])  # fmt: skip
def test_every_manifest_field_is_checked_before_use(tmp_path, capsys, field, value):
    path = _store(tmp_path / "s")
    body = _body(path)
    *parents, last = field.split(".")
    target = body
    for key in parents:
        target = target[int(key)] if isinstance(target, list) else target[key]
    target[last] = value
    _write_manifest(path, body)
    _refused_everywhere(path, capsys, "bad record field")


def test_a_first_seq_past_every_segment_deletes_nothing(tmp_path, capsys):
    # It made the writer delete the active segment as a segment dropped by retention.
    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True, sync_every_ms=None) as s:
        for i in range(3):
            s.put_window("/a", [(i, "1")])
    body = _body(path)
    assert body["segments"] == []
    body["first_seq"], body["checkpoint"] = 1000, {}
    _write_manifest(path, body)
    _refused_everywhere(path, capsys, "first_seq is 1000", "00000000000000000000.seg")


def test_an_end_seq_past_the_log_is_refused_not_skipped(tmp_path, capsys):
    # Readers skipped the active segment (`cat` exit 0) and the writer crashed with
    # struct.error, leaving a segment named 18446744073709551621.seg.
    path = _store(tmp_path / "s")
    body = _body(path)
    body["segments"][-1]["end_seq"] += 5
    _write_manifest(path, body)
    _refused_everywhere(path, capsys, "segments[1].end_seq is 13", "00000000000000000008.seg")


def test_a_rebuilt_manifest_repairs_a_forged_one(tmp_path):
    path = _store(tmp_path / "s")
    with cclogfs.open_store(path, readonly=True) as s:
        want = [(w.seq, list(w.messages())) for w in s.query()]
    body = _body(path)
    body["segments"][0]["streams"] = []
    _write_manifest(path, body)
    report = repair_store(str(path))
    assert any("rebuilt MANIFEST" in a for a in report.actions)
    with cclogfs.open_store(path, readonly=True) as s:
        assert [(w.seq, list(w.messages())) for w in s.query()] == want


# -- item 3: sizes checked before reading ------------------------------------------------


def _peak_rss_mib(code: str) -> tuple[int, str]:
    """Run `code` in a fresh interpreter; its peak RSS in MiB and its last output line."""
    # VmHWM, not ru_maxrss: a child's ru_maxrss starts at its parent's (the test worker's,
    # hundreds of MiB after the crash states), VmHWM at its own new address space.
    wrapper = (f"import sys\n{code}\n"
               "print(next(int(l.split()[1]) for l in open('/proc/self/status') if l.startswith('VmHWM:')) // 1024)")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", wrapper], capture_output=True, text=True, timeout=300)
    assert "Traceback" not in out.stderr, out.stderr
    lines = out.stdout.strip().splitlines()
    return int(lines[-1]), "\n".join(lines[:-1])


_OPEN_AND_READ = """
import cclogfs
from cclogfs.errors import CclogError
from cclogfs.store import check_store
path, readonly = sys.argv[1] if len(sys.argv) > 1 else {path!r}, {readonly!r}
try:
    with cclogfs.open_store(path, readonly=readonly) as s:
        print("read", sum(len(list(w.messages())) for w in s.query()))
except CclogError as err:
    print("error", str(err).splitlines()[0][:200])
print("fsck", len(check_store(path, deep=True).errors))
"""


def _sparse(file: Path, size: int) -> None:
    with open(file, "r+b" if file.exists() else "wb") as f:
        f.truncate(size)


@pytest.mark.parametrize("readonly", [True, False])
def test_a_sparse_8_gib_manifest_is_refused_on_its_size(tmp_path, readonly):
    path = _store(tmp_path / "s")
    _sparse(path / MANIFEST, 8 * GiB)
    rss, out = _peak_rss_mib(_OPEN_AND_READ.format(path=str(path), readonly=readonly))
    assert "error" in out and "MANIFEST" in out and "over the" in out, out
    assert rss < 400, rss  # it peaked at 16.4 GiB
    assert (path / MANIFEST).stat().st_size == 8 * GiB  # not touched


def test_a_sparse_4_gib_index_is_never_read(tmp_path):
    path = _store(tmp_path / "s")
    idx = path / "00000000000000000000.idx"
    _sparse(idx, 4 * GiB)
    rss, out = _peak_rss_mib(_OPEN_AND_READ.format(path=str(path), readonly=True))
    assert "read 30" in out and "fsck 0" in out, out  # rebuilt from the segment; a warning
    assert rss < 400, rss  # it peaked at 8.2 GiB
    report = check_store(str(path))
    assert any(f.where == idx.name and "over the" in f.what for f in report.findings)


def test_the_lock_holder_is_read_bounded(tmp_path):
    path = _store(tmp_path / "s")
    with cclogfs.open_store(path) as _writer:
        _sparse(path / "LOCK", 8 * GiB)
        rss, out = _peak_rss_mib(f"""
import cclogfs
from cclogfs.errors import StoreLockedError
try:
    cclogfs.open_store({str(path)!r})
except StoreLockedError as err:
    print("locked")
""")
    assert out == "locked" and rss < 400, (out, rss)


# -- item 5: forged indexes -------------------------------------------------------------


def _forged_index(names: bytes, entries: list | None, first_seq: int, size: int) -> bytes:
    entries = entries or []
    head = INDEX_HEADER.pack(INDEX_MAGIC, 1, 0, first_seq, size, len(entries), len(names))
    body = head + names + b"".join(INDEX_ENTRY.pack(*e) for e in entries)
    return body + struct.pack("<Q", xxh3(body))


def _entries_with(path, **change):
    idx = path / "00000000000000000000.idx"
    size = (path / "00000000000000000000.seg").stat().st_size
    index = SegmentIndex.decode(idx.read_bytes(), 0, size)
    entries = list(index.entries)
    first = list(entries[0])
    for key, value in change.items():  # a field of the first entry, by its name in FORMAT.md
        first[getattr(index_mod, key.upper())] = value
    entries[0] = tuple(first)
    return index.names, entries, size


@pytest.mark.parametrize("forge", [
    lambda names, e: (b"[" * 50_000, e),
    lambda names, e: (json.dumps({"a": 1}).encode(), e),
    lambda names, e: (json.dumps([1]).encode(), e),
    lambda names, e: (json.dumps(["/odom", "/odom"]).encode(), e),
    lambda names, e: (b"\xff\xfe", e),
    lambda names, e: (json.dumps(names).encode(), "length=9223372036854775807"),
    lambda names, e: (json.dumps(names).encode(), "offset=18446744073709551615"),
    lambda names, e: (json.dumps(names).encode(), "offset=0"),
    lambda names, e: (json.dumps(names).encode(), "count=0"),
    lambda names, e: (json.dumps(names).encode(), "stream=7"),
])  # fmt: skip
def test_a_forged_index_is_rebuilt_and_every_read_is_right(tmp_path, forge):
    path = _store(tmp_path / "s")
    with cclogfs.open_store(path, readonly=True) as s:
        want = [(w.seq, list(w.messages())) for w in s.query()]
    names, entries, size = _entries_with(path)
    raw_names, change = forge(names, entries)
    if isinstance(change, str):
        key, value = change.split("=")
        names, entries, size = _entries_with(path, **{key: int(value)})
    idx = path / "00000000000000000000.idx"
    idx.write_bytes(_forged_index(raw_names, entries, 0, size))
    report = check_store(str(path), deep=True)
    assert not report.errors and any(f.where == idx.name for f in report.findings)
    with cclogfs.open_store(path, readonly=True) as s:
        assert [(w.seq, list(w.messages())) for w in s.query()] == want
    with cclogfs.open_store(path) as s:  # the writer rebuilds it and writes it back
        assert [(w.seq, list(w.messages())) for w in s.query()] == want
    assert not check_store(str(path)).findings


# -- item 5: forged record meta and config ----------------------------------------------


def _forge_last_record(path, *, meta=None, config=None):
    """Replace the last record of the active segment by one with this meta or config,
    every checksum valid (the active segment is scanned, not indexed)."""
    seg = path / "00000000000000000008.seg"
    with cclogfs.open_store(path, readonly=True) as s:
        w = max(s.query(), key=lambda w: w.seq)
        h, payload = w._read()
    rec = pack_record(seq=h.seq, start_ns=h.start_ns, end_ns=h.end_ns, count=h.count, codec=h.codec,
                      name=h.name.encode(), config=h.config if config is None else config,
                      meta=h.meta if meta is None else meta, raw_len=h.raw_len, payload=payload,
                      synced=h.synced)  # fmt: skip
    data = seg.read_bytes()
    seg.write_bytes(data[: w.offset] + rec)
    return w.offset


@pytest.mark.parametrize("meta, config", [
    (b"{", None), (b"[1]", None), (b"[" * 5000, None), (b"\xff", None),
    (None, b"{"), (None, b"[" * 3000), (None, b'{"level":3}'), (None, b'{"id":"zstd","level":"x"}'),
    (None, b'{"id":"zstd","level":3,"extra":1}'), (None, b'{"id":"columnar","version":[]}'),
])  # fmt: skip
def test_a_forged_meta_or_config_is_a_one_line_error(tmp_path, capsys, meta, config):
    path = _store(tmp_path / "s")
    offset = _forge_last_record(path, meta=meta, config=config)
    before = _files(path)
    with cclogfs.open_store(path, readonly=True) as s:
        w = max(s.query(), key=lambda w: w.seq)
        with pytest.raises(CclogError) as err:
            w.meta if meta is not None else list(w.messages())  # noqa: B018
        msg = str(err.value)
        assert "\n" not in msg and "00000000000000000008.seg" in msg and f"offset {offset}" in msg, msg
    report = check_store(str(path), deep=True)
    assert any("00000000000000000008.seg@" in f.where and f.severity == "error" for f in report.findings)
    # info shows the meta's msgtype and the codec config; cat decodes with the config.
    not_object = not (meta or config).startswith(b"{") or (meta or config) == b"{"
    for cmd in (["fsck", "--deep"], *([["info"]] if not_object else []), *([["cat"]] if config else [])):
        assert main([*cmd, str(path)]) != 0, cmd
    out = capsys.readouterr()
    assert "Traceback" not in out.err + out.out
    assert _files(path) == before


# -- item 5: entries that are not files -------------------------------------------------


@pytest.mark.parametrize("make", ["dangling symlink", "directory"])
@pytest.mark.parametrize("name", ["00000000000000000100.seg", "00000000000000000000.seg"])
def test_a_non_file_named_like_a_segment_is_named_in_one_line(tmp_path, capsys, make, name):
    path = _store(tmp_path / "s")
    target = path / name
    if target.exists():
        target.unlink()
    if make == "directory":
        target.mkdir()
    else:
        target.symlink_to(tmp_path / "nowhere")
    for readonly in (True, False):
        with pytest.raises(StoreError) as err:
            cclogfs.open_store(path, readonly=readonly)
        assert "\n" not in str(err.value) and name in str(err.value)
    report = check_store(str(path), deep=True)
    assert report.errors and name in str(report.errors[0])
    for cmd in (["cat"], ["info"], ["fsck"], ["fsck", "--deep"]):
        assert main([*cmd, str(path)]) != 0
    out = capsys.readouterr()
    assert "Traceback" not in out.err + out.out and name in out.err + out.out
    assert target.is_symlink() or target.is_dir()


# -- item 5: aging on text that is not JSON ---------------------------------------------


@pytest.mark.parametrize("text", ["00", "]", "[1,2]]", '{"a":1}}', "{0", '{"a" 1.5]', "1.5{1.5"])
def test_aging_text_that_is_not_json_is_an_input_error(text):
    try:
        Policy(rules=[parse_rule("*=0.1")]).round_text(text)
    except InvalidInputError as err:
        assert "not JSON" in str(err)


@pytest.mark.parametrize("lower", [1, 3])
def test_an_end_seq_short_of_the_log_is_refused_not_dropped(tmp_path, capsys, lower):
    # Issue 16: a lower end_seq made the active segment (starting at the real end) a
    # sequence gap, which the writer deleted: silent loss of synced records.
    path = _store(tmp_path / "s")
    body = _body(path)
    body["segments"][-1]["end_seq"] -= lower
    _write_manifest(path, body)
    _refused_everywhere(path, capsys, f"segments[1].end_seq is {8 - lower}", "00000000000000000004.seg")


def test_an_end_seq_short_of_the_log_is_refused_with_its_index_gone(tmp_path, capsys):
    # Without the sealed segment's index the check scans the segment instead.
    path = _store(tmp_path / "s")
    (path / "00000000000000000004.idx").unlink()
    body = _body(path)
    body["segments"][-1]["end_seq"] -= 1
    _write_manifest(path, body)
    _refused_everywhere(path, capsys, "segments[1].end_seq is 7", "00000000000000000004.seg")


def test_an_end_seq_short_of_a_segment_with_declared_damage_is_refused(tmp_path, capsys):
    # The end_seq check returned early for a last sealed segment whose damage the manifest
    # declares: a lower end_seq then made the writer delete the active segment's synced
    # windows again (issue 16's loss, through a segment fsck had already reported).
    path = tmp_path / "s"
    crash = (f"import cclogfs, json, os\n"
             f"s = cclogfs.open_store({str(path)!r}, create=True, codec='none', sync_every_ms=None)\n"
             f"for i in range(6):\n"
             f"    s.put_window('/odom', [(i * 10 + k, json.dumps({{'x': 'abcdefgh' * 4}})) for k in range(3)])\n"
             f"    s.sync()\n"
             f"os._exit(9)\n")  # fmt: skip
    subprocess.run([sys.executable, "-c", crash], check=False)
    seg = path / "00000000000000000000.seg"
    data = bytearray(seg.read_bytes())
    data[200] ^= 0xFF  # the first record's payload, below the synced point: kept, declared
    seg.write_bytes(bytes(data))
    with cclogfs.open_store(path, sync_every_ms=None) as s:
        assert [d["first_seq"] for d in s.damage()] == [0]
        s.seal()
        for i in range(6, 9):
            s.put_window("/odom", [(i * 10, json.dumps({"x": i}))])
    body = _body(path)
    assert body["segments"][-1]["damaged"] and body["segments"][-1]["end_seq"] == 6
    body["segments"][-1]["end_seq"] -= 2
    _write_manifest(path, body)
    _refused_everywhere(path, capsys, "segments[0].end_seq is 4", "00000000000000000000.seg")
