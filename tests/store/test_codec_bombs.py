"""What reading one record costs, whatever its bytes (issue 16 item 3, FORMAT.md "Limits").

A record's checksummed header states its window's raw size (`raw_len`), and every decoder
holds its work to a multiple of it; a record this version writes holds at most
MAX_RECORD_RAW, a larger window is split into several records, and a read decodes no record
above DECODE_RAW_LIMIT. Here the worst record we could forge for each codec (a tiny payload
that decodes to the most Python objects, or to the largest columnar body) is read in a fresh
process whose peak RSS (VmHWM) is measured: it must stay within the bound FORMAT.md states.

    python tests/store/test_codec_bombs.py [RAW_MIB]   # the peak of each forged record
"""

import json
import lzma
import os
import struct
import subprocess
import sys
import textwrap

import pytest
import xxhash
import zstandard

import cclogfs
from cclogfs.codecs import codec_from_config, frame
from cclogfs.store.format import SEGMENT_HEADER_SIZE, pack_record

MiB = 1 << 20
# FORMAT.md, "Limits": reading one record costs at most 16 x its raw_len beyond the interpreter.
PEAK_FACTOR = 16

READ = textwrap.dedent("""
    import json, sys
    from cclogfs.errors import CclogError
    from cclogfs.store import open_store

    def rss():
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmHWM:")) // 1024

    with open_store(sys.argv[1], readonly=True) as store:
        (window,) = store.query()
        before = rss()
        try:
            n, error = sum(1 for _ in window.messages()), None
        except CclogError as err:
            n, error = 0, str(err)[:200]
    print(json.dumps({"peak_mib": rss() - before, "messages": n, "error": error}))
""")


def _empty(raw_len: int) -> tuple[int, bytes]:
    """Empty texts: the most messages raw_len allows, each a distinct stamp."""
    n = min((raw_len - 4) // 12, 1 << 24)
    data = frame(list(range(n)), [""] * n)
    return n, data + b"\0" * (raw_len - len(data))  # (padding only when MAX_COUNT caps n: then not valid)


def _columnar(texts: list[str], raw_len: int) -> tuple[int, int, bytes, dict]:
    """A valid columnar record of these texts, the first padded with spaces to raw_len."""
    texts[0] += " " * (raw_len - 4 - 12 * len(texts) - sum(map(len, texts)))
    codec = codec_from_config({"id": "columnar"})
    return len(texts), 4, codec.encode(list(range(len(texts))), texts), codec.get_config()


def _zero_body(raw_len: int) -> tuple[int, int, bytes, dict]:
    """The largest body the columnar codec allows for raw_len (9 x + 1 KiB), all zeros."""
    body_len = 9 * raw_len + 1024
    data = zstandard.ZstdCompressor(level=1).compress(b"\0" * body_len)
    payload = struct.pack("<BII", 4, body_len, xxhash.xxh32_intdigest(data)) + data
    return _empty(raw_len)[0], 4, payload, {"id": "columnar", "version": 4, "level": 3}


def _payload(case: str, raw_len: int) -> tuple[int, int, bytes, dict]:
    """(count, codec number, payload, config) of a forged record of `raw_len`: each decodes to
    a window of that size (or claims to), with the most Python objects we could make."""
    if case in ("none", "zstd", "lzma"):
        n, data = _empty(raw_len)
    if case == "none":
        return n, 1, data, {"id": "none"}
    if case == "zstd":
        return n, 2, zstandard.ZstdCompressor(level=1).compress(data), {"id": "zstd", "level": 1}
    if case == "lzma":
        return n, 3, lzma.compress(data, preset=0), {"id": "lzma", "preset": 0}
    if case == "columnar-digits":  # 19-digit integers counting up: a few bytes of payload
        return _columnar([str(10**18 + i) for i in range((raw_len - 4) // 31)], raw_len)
    if case == "columnar-short":  # two-digit integers: the most distinct texts a template renders
        return _columnar([str(10 + i % 90) for i in range((raw_len - 4) // 14)], raw_len)
    return _zero_body(raw_len)


def forge(path, case: str, raw_len: int) -> None:
    """A store whose one record is the forged `case`, appended after a clean close."""
    with cclogfs.open_store(path, create=True):
        pass
    count, codec, payload, config = _payload(case, raw_len)
    record = pack_record(seq=0, start_ns=0, end_ns=count - 1, count=count, codec=codec, name=b"/a",
                         config=json.dumps(config, separators=(",", ":")).encode(), meta=b"{}",
                         raw_len=raw_len, payload=payload, synced=SEGMENT_HEADER_SIZE)  # fmt: skip
    with open(os.path.join(path, "00000000000000000000.seg"), "ab") as f:
        f.write(record)


def peak(path) -> dict:
    done = subprocess.run([sys.executable, "-c", READ, str(path)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


CASES = ["none", "zstd", "lzma", "columnar-digits", "columnar-short", "columnar-zero-body"]


@pytest.mark.parametrize("case", CASES)
def test_the_worst_record_of_each_codec_reads_within_the_stated_bound(tmp_path, case):
    from cclogfs.store.format import DECODE_RAW_LIMIT

    forge(tmp_path / "s", case, DECODE_RAW_LIMIT)
    got = peak(tmp_path / "s")
    assert got["peak_mib"] < PEAK_FACTOR * DECODE_RAW_LIMIT // MiB, got


@pytest.mark.parametrize("case", ["zstd", "columnar-zero-body"])
def test_a_record_over_the_decode_limit_is_refused_before_it_is_decoded(tmp_path, case):
    # Under the old rule (raw_len up to 256 MiB) a 74 KB columnar record peaked at 2.4 GiB.
    from cclogfs.store.format import DECODE_RAW_LIMIT

    forge(tmp_path / "s", case, 2 * DECODE_RAW_LIMIT)
    got = peak(tmp_path / "s")
    assert got["error"] and "record at offset 32 (seq 0)" in got["error"] and "limit" in got["error"], got
    assert got["peak_mib"] < 64, got


if __name__ == "__main__":
    import tempfile

    raw = int(float(sys.argv[1]) * MiB) if len(sys.argv) > 1 else None
    if raw is None:
        from cclogfs.store.format import DECODE_RAW_LIMIT as raw
    for case in sys.argv[2:] or CASES:
        with tempfile.TemporaryDirectory() as tmp:
            forge(os.path.join(tmp, "s"), case, raw)
            size = os.path.getsize(os.path.join(tmp, "s", "00000000000000000000.seg"))
            print(f"{case}: raw_len {raw / MiB:.0f} MiB, segment {size:,} bytes: {peak(os.path.join(tmp, 's'))}", flush=True)


# -- windows over the record limit are split ---------------------------------------------


def _window(n=300):
    # Stamps repeat (three messages a stamp), so some splits fall between equal stamps.
    return [(i // 3, json.dumps({"i": i, "pad": "x" * (i % 50)})) for i in range(n)]


def _cat(path, capsys, *args):
    from cclogfs.cli import main

    assert main(["cat", str(path), *args]) == 0
    return capsys.readouterr().out


def _record(path, split_at=None, monkeypatch=None):
    from cclogfs.store import encode

    if split_at is not None:
        monkeypatch.setattr(encode, "MAX_RECORD_RAW", split_at)
    with cclogfs.open_store(path, create=True, codec="zstd", segment_records=4) as store:
        store.put_window("/b", [(0, "1"), (150, "2")])
        receipt = store.put_window("/a", _window(), meta={"k": 1})
        store.put_window("/b", [(100, "3")])
    monkeypatch.undo() if monkeypatch is not None else None
    return receipt


def test_a_window_over_the_record_limit_is_stored_as_consecutive_records(tmp_path, monkeypatch, capsys):
    whole = _record(tmp_path / "whole")
    split = _record(tmp_path / "split", 4096, monkeypatch)
    assert whole.records == 1 and split.records > 3
    assert (split.seq, split.count) == (whole.seq, whole.count)
    assert split.raw_bytes == whole.raw_bytes + 4 * (split.records - 1)  # each record's framing has its count
    with cclogfs.open_store(tmp_path / "split", readonly=True) as store:
        parts = list(store.query("/a"))
        assert [w.seq for w in parts] == list(range(split.seq, split.seq + split.records))
        assert all(w.meta == {"k": 1} for w in parts)
        got = [m for w in parts for m in w.messages()]
        assert got == _window()
        assert all(4 + sum(12 + len(t) for _, t in w.messages()) <= 4096 for w in parts)
        assert [w.seq for w in store.query("/b")] == [0, split.seq + split.records]
    # `cat` prints the same bytes from both stores: every stream, and one time range.
    for args in ([], ["--topic", "/a"], ["--start", "40ns", "--end", "60ns"]):
        assert _cat(tmp_path / "split", capsys, *args) == _cat(tmp_path / "whole", capsys, *args)


def test_a_window_of_a_whole_run_is_split_at_the_real_limit(tmp_path):
    # tuc_corridor.mcap's 38 minutes of /odom as one window is 20 MB of canonical framing.
    text = json.dumps({"pose": [0.123456789] * 80})
    messages = [(i * 100_000_000, text) for i in range((20 << 20) // (12 + len(text)))]
    with cclogfs.open_store(tmp_path / "s", create=True, codec="zstd") as store:
        receipt = store.put_window("/odom", messages)
    assert receipt.records == 2
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [m for w in store.query() for m in w.messages()] == messages


def test_a_message_larger_than_a_record_holds_is_refused(tmp_path, monkeypatch):
    from cclogfs.errors import InvalidInputError
    from cclogfs.store import encode

    monkeypatch.setattr(encode, "MAX_RECORD_RAW", 4096)
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        with pytest.raises(InvalidInputError, match="message 1 for '/a' is 5002 bytes, over what one record holds"):
            store.put_window("/a", [(0, "1"), (1, json.dumps("x" * 5000))])
        assert list(store.query()) == []


def _killed_between_parts(path, at_seq=2, sync_every_bytes=1):
    """A writer killed (kill -9) while it appends the parts of a split window: /b at seq 0,
    then /a's parts from seq 1, the process dying as it is about to append seq `at_seq`, the
    parts before handed to the OS (as a part over the 1 MiB write buffer would be)."""
    child = textwrap.dedent(f"""
        import json, os
        import cclogfs
        from cclogfs.store import encode
        from cclogfs.store.store import Store
        encode.MAX_RECORD_RAW = 4096
        append = Store._append
        def dying(self, name, enc, **kw):
            if self.active.next_seq == {at_seq}:
                self.active.flush()
                os._exit(9)
            return append(self, name, enc, **kw)
        Store._append = dying
        s = cclogfs.open_store({str(path)!r}, create=True, codec="none", sync_every_ms=None,
                               sync_every_bytes={sync_every_bytes})
        s.put_window("/b", [(0, "1")])
        s.put_window("/a", [(i, json.dumps({{"i": i, "pad": "p" * 100}})) for i in range(100)])
    """)  # fmt: skip
    assert subprocess.run([sys.executable, "-c", child]).returncode == 9


@pytest.mark.parametrize("at_seq", [2, 3])
def test_a_crash_between_the_parts_of_a_split_window_is_not_silent(tmp_path, capsys, at_seq):
    # Before the PART flag the parts written before the kill read as a whole window: `cat`
    # printed that prefix with exit 0 and fsck found the store clean. (sync_every_bytes=1:
    # the group commit after the first part, which the old writer ran, made it durable.)
    from cclogfs.cli import main
    from cclogfs.store import check_store

    path = tmp_path / "s"
    _killed_between_parts(path, at_seq)
    with cclogfs.open_store(path, readonly=True) as store:  # a reader never shows a prefix of the window
        assert [w.name for w in store.query()] == ["/b"]
    assert main(["cat", str(path)]) == 0 and capsys.readouterr().out.count("\n") == 1
    report = check_store(str(path), deep=True)
    assert report.errors == [] and len(report.findings) == 1, report.findings
    assert f"seqs 1..{at_seq - 1} are parts of a split window whose last part is missing" in report.findings[0].what
    assert "a put never acknowledged; the writer will cut" in report.findings[0].what
    with cclogfs.open_store(path) as store:  # the writer cuts it like a torn tail, keeping no side file
        (problem,) = store.recovery.problems
        assert (problem.reason, problem.intact_after, problem.kept_in) == ("unfinished put", 0, "")
        assert store.put_window("/c", [(5, "2")]).seq == 1
    with cclogfs.open_store(path, readonly=True) as store:
        assert store.recovery.clean and [w.name for w in store.query()] == ["/b", "/c"]
    assert sorted(os.listdir(path)) == ["00000000000000000000.idx", "00000000000000000000.seg", "LOCK", "MANIFEST",
                                        "RESERVE"]  # fmt: skip


# `cat` breaks ties between equal stamps of different streams by window order, and a split
# window's later parts start later than the window: the parts keep their first part's place.
def test_cat_orders_equal_stamps_of_a_split_window_as_of_the_whole(tmp_path, monkeypatch, capsys):
    from cclogfs.store import encode

    def record(path, split_at):
        monkeypatch.setattr(encode, "MAX_RECORD_RAW", split_at)
        with cclogfs.open_store(path, create=True, codec="zstd") as store:
            store.put_window("/b", [(48, '"b"')])  # 48: a stamp a part of /a ends and the next starts at
            receipt = store.put_window("/a", _window(), meta={"k": 1})
        monkeypatch.undo()
        return receipt

    assert record(tmp_path / "split", 4096).records > 1 and record(tmp_path / "whole", 1 << 24).records == 1
    with cclogfs.open_store(tmp_path / "split", readonly=True) as store:
        assert any(w.start_ns == 48 for w in store.query("/a"))
    assert _cat(tmp_path / "split", capsys) == _cat(tmp_path / "whole", capsys)


def test_records_an_older_version_wrote_over_the_limit_read_with_max_record_mib(tmp_path, capsys, monkeypatch):
    # Older versions wrote records of up to 256 MiB: the commands read them when told to.
    from cclogfs.cli import main
    from cclogfs.store import format

    monkeypatch.setattr(format, "DECODE_RAW_LIMIT", format.DECODE_RAW_LIMIT)  # main() sets it for its process
    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True):
        pass
    texts = [json.dumps("x" * (1 << 20)) for _ in range(17)]  # 17 MiB of window in one record
    raw = frame(list(range(17)), texts)
    record = pack_record(seq=0, start_ns=0, end_ns=16, count=17, codec=1, name=b"/a", config=b'{"id":"none"}',
                         meta=b"{}", raw_len=len(raw), payload=raw, synced=SEGMENT_HEADER_SIZE)  # fmt: skip
    with open(path / "00000000000000000000.seg", "ab") as f:
        f.write(record)
    assert main(["cat", str(path)]) == 1
    err = capsys.readouterr().err
    assert "record at offset 32 (seq 0) holds a" in err and "pass --max-record-mib N (N at most 256) to cat" in err
    assert main(["fsck", "--deep", str(path)]) == 1 and "--max-record-mib" in capsys.readouterr().out
    assert main(["cat", str(path), "--max-record-mib", "18"]) == 0
    assert capsys.readouterr().out.count("\n") == 17
    assert main(["fsck", "--deep", "--max-record-mib", "18", str(path)]) == 0
    capsys.readouterr()
    with pytest.raises(SystemExit):
        main(["cat", str(path), "--max-record-mib", "300"])
    assert "'300' is not a whole number of MiB from 16 to 256" in capsys.readouterr().err
