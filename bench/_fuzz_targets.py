"""Fuzz targets: one function per parser of untrusted bytes (issue 16, "Fuzzing").

Each target takes arbitrary bytes and must either return or raise one of the project's
errors (`CclogError`, or the parser's documented `RecordError`/`JsonlLineError`); anything
else (IndexError, KeyError, RecursionError, MemoryError, struct.error ...) is a crash.
Checksums are switched off while a target runs (`format.CHECKSUMS_OFF`), so random bytes
reach the parsing past them instead of stopping at the first CRC.

Used by tests/fuzz (the committed corpus replayed, and Hypothesis) and by
`python -m bench fuzz` (atheris, coverage-guided, N seconds per target).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import struct
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from cclogfs.errors import CclogError
from cclogfs.jsontext.lines import JsonlLineError, parse_line
from cclogfs.store import format as fmt
from cclogfs.store.format import RecordError

ALLOWED: tuple[type[BaseException], ...] = (CclogError, RecordError, JsonlLineError)
SCRATCH = Path("/dev/shm") if Path("/dev/shm").is_dir() else Path(tempfile.gettempdir())


@contextlib.contextmanager
def checksums_off() -> Iterator[None]:
    kinds = {"record", "index", "manifest", "segment header"}
    before = set(fmt.CHECKSUMS_OFF)
    fmt.CHECKSUMS_OFF.update(kinds)
    try:
        yield
    finally:
        fmt.CHECKSUMS_OFF.clear()
        fmt.CHECKSUMS_OFF.update(before)


def _u(data: bytes, i: int, size: int = 4) -> int:
    chunk = data[i : i + size].ljust(size, b"\0")
    return int.from_bytes(chunk, "little")


# -- store -------------------------------------------------------------------------------


def record_header(data: bytes) -> None:
    from cclogfs.store.records import BytesAt, read_record

    header, _payload = read_record(BytesAt(data), 0, len(data))
    fmt.check_fields(header)


def segment_scan(data: bytes) -> None:
    """Records walked in log order, then the salvaging scan recovery runs, on a file."""
    from cclogfs.store.fs import FileSystem
    from cclogfs.store.records import BytesAt, intact_in, records

    from bench._util import BytesFile
    from cclogfs.store.segment import open_segment, scan

    with contextlib.suppress(*ALLOWED):
        for _rec in records(BytesAt(data), 0, len(data), _u(data, 8, 8)):
            pass
    with contextlib.suppress(*ALLOWED):
        for _found in intact_in(BytesFile(data), 0, 1, len(data)):
            pass
    fs = FileSystem()
    with tempfile.NamedTemporaryFile(dir=SCRATCH, suffix=".seg") as f:
        f.write(data)
        f.flush()
        seg, _ok = open_segment(fs, f.name, write=False)
        try:
            scan(seg, salvage=True)
        finally:
            fs.close(seg.fd)


def index(data: bytes) -> None:
    from cclogfs.store.index import SegmentIndex

    # The first_seq and segment_size it is checked against are the ones it states.
    head = data[: fmt.INDEX_HEADER.size].ljust(fmt.INDEX_HEADER.size, b"\0")
    magic, version, flags, first_seq, size, count, names_len = fmt.INDEX_HEADER.unpack(head)
    if data[:1] != b"\0":  # make the lengths fit the bytes, so that most inputs get past them
        body = max(0, len(data) - fmt.INDEX_HEADER.size - 8)
        names_len = min(names_len, body)
        count = (body - names_len) // 56
        head = fmt.INDEX_HEADER.pack(magic, version, flags, first_seq, size, count, names_len)
        data = head + data[fmt.INDEX_HEADER.size : fmt.INDEX_HEADER.size + names_len + 56 * count] + data[-8:]
    idx = SegmentIndex.decode(data, first_seq, size)
    idx.stream_stats()
    for entries in idx.streams.values():
        entries.overlapping(fmt.MIN_NS, fmt.MAX_NS)


def manifest(data: bytes) -> None:
    """The MANIFEST as Manifest.load checks it, then what the store reads of a version."""
    from cclogfs.store.manifest import Manifest
    from cclogfs.store.manifest_check import body_version, check_body

    body = fmt.unpack_manifest(data)
    try:
        body_version(body)
    finally:
        check_body(body)  # whatever the version field says
    m = Manifest(body)
    m.sealed, m.end_seq, m.named_files(), m.damage(), m.checkpoint, m.quarantine, m.dropped  # noqa: B018
    m.without_oldest() if m.segments else m.with_sealed({"first_seq": m.end_seq})


def manifest_json(data: bytes) -> None:
    """A manifest body as JSON text (the fuzzer need not build the binary framing)."""
    manifest(_frame_manifest(data))


def _frame_manifest(text: bytes) -> bytes:
    head = fmt.MANIFEST_HEADER.pack(fmt.MANIFEST_MAGIC, fmt.FILE_VERSION, 0, len(text)) + text
    return head + struct.pack("<I", fmt.crc32c(head))


def codec_payload(data: bytes) -> None:
    """A record payload for each codec: byte 0 picks the codec, then count, raw_len."""
    from cclogfs.codecs import codec_from_config

    codec = codec_from_config(("none", "zstd", "lzma", "columnar")[data[:1][0] % 4 if data else 0])
    count, raw_len = _u(data, 1) % (fmt.MAX_COUNT + 1), _u(data, 5) % (fmt.MAX_RAW + 1)
    codec.decode(data[9:], count=count, raw_len=raw_len)


def record_config_meta(data: bytes) -> None:
    """A record whose checksums hold and whose config and meta are these bytes, read as
    `cat`, `info` and `fsck --deep` read it."""
    from cclogfs.store.window import Window

    split = data.find(b"\0")
    config, meta = (data, b"{}") if split < 0 else (data[:split], data[split + 1 :])
    header = fmt.RecordHeader(1, 2, 0, 0, 0, 0, 0, 1, 4, "/x", config, meta, 0, 0, 0)
    seg = _FakeSegment()
    w = Window("/x", 0, 0, 0, 1, seg, 32, 0, (header, b""))
    for read in (lambda: w.meta, lambda: w.codec_config, lambda: w.aged, lambda: list(w.messages())):
        with contextlib.suppress(*ALLOWED):
            read()


class _FakeSegment:
    path, sealed_size, fd = "fuzz.seg", -1, 0


# -- other parsers -----------------------------------------------------------------------


def jsonl_line(data: bytes) -> None:
    try:
        line = data.decode("utf-8")
    except UnicodeDecodeError:
        return
    parse_line(line)


def jsonl_split(data: bytes) -> None:
    """The compiled JSONL splitter (cclogfs/ingest/_jsonl_split.c) against the Python path
    on each line of `data`: a line it takes must give the Python path's message, and json
    must read the line as exactly that object; a line it declines (None) is read by the
    Python path alone. A difference is an AssertionError, a crash."""
    from cclogfs.ingest import jsonl

    if jsonl._split_lines_c is None:
        return
    lines = [line + b"\n" for line in data.split(b"\n")]
    lines[-1] = lines[-1][:-1]  # as readlines gives them: the last without its ending
    for line, got in zip(lines, jsonl._split_lines_c(lines, jsonl.SourceMessage)):
        if got is not None:
            assert got == python_message(line), line


def python_message(line: bytes):
    """The message JsonlSource's Python path reads from one line, checked against json;
    AssertionError when there is none (the line is not a message)."""
    from cclogfs.ingest.base import SourceMessage
    from cclogfs.ingest.jsonl import _split_python

    message = _split_python([line])[0]
    if message is None:
        text = line.decode("utf-8").removesuffix("\n").removesuffix("\r")  # UnicodeDecodeError: a crash
        try:
            message = SourceMessage(*parse_line(text))
        except JsonlLineError as err:
            raise AssertionError(f"the Python path refuses the line: {err}") from None
    whole = json.loads(line)
    assert list(whole) == ["topic", "stamp_ns", "msg"] and whole["topic"] == message.topic
    assert whole["stamp_ns"] == message.stamp_ns and json.loads(message.text) == whole["msg"]
    return message


def aging_policy(data: bytes) -> None:
    """Policy.round_text on any text (aging rounds the numbers of stored messages)."""
    from cclogfs.upkeep.policy import Policy, parse_rule

    text = data.decode("utf-8", errors="replace")
    Policy(rules=[parse_rule("*=0.01")]).round_text(text)


def model_files(data: bytes) -> None:
    """A classifier model directory: model.json (bytes before the first NUL) and
    model.npz (the rest), the npz checksum made to match (the check switched off)."""
    from cclogfs.classifier.model import OneClassModel

    split = data.find(b"\0")
    head, blob = (data, b"") if split < 0 else (data[:split], data[split + 1 :])
    try:
        header = json.loads(head)
    except (ValueError, RecursionError):
        header = None
    if isinstance(header, dict):
        header["npz_sha256"] = hashlib.sha256(blob).hexdigest()
        head = json.dumps(header).encode()
    with tempfile.TemporaryDirectory(dir=SCRATCH) as tmp:
        Path(tmp, "model.json").write_bytes(head)
        Path(tmp, "model.npz").write_bytes(blob)
        OneClassModel.load(tmp)


def rosbag1(data: bytes) -> None:
    """A ROS 1 bag file, read whole through `open_source` (its salvage reader included)."""
    from cclogfs.ingest import open_source

    with tempfile.TemporaryDirectory(dir=SCRATCH) as tmp:
        path = Path(tmp, "f.bag")
        path.write_bytes(b"#ROSBAG V2.0\n" + data)
        with open_source(path, format="rosbag1") as src:
            for _msg in src:
                pass


TARGETS: dict[str, Callable[[bytes], None]] = {
    "record_header": record_header,
    "segment_scan": segment_scan,
    "index": index,
    "manifest": manifest,
    "manifest_json": manifest_json,
    "codec_payload": codec_payload,
    "record_config_meta": record_config_meta,
    "jsonl_line": jsonl_line,
    "jsonl_split": jsonl_split,
    "aging_policy": aging_policy,
    "model_files": model_files,
    "rosbag1": rosbag1,
}


def run_one(name: str, data: bytes) -> None:
    """Run target `name` on `data`; a project error is a fine outcome, anything else raises."""
    with checksums_off():
        try:
            TARGETS[name](data)
        except ALLOWED:
            pass


@functools.lru_cache(maxsize=None)
def _seeds(name: str) -> tuple[bytes, ...]:
    return tuple(_SEEDS.get(name, lambda: [b""])())


def seeds(name: str) -> list[bytes]:
    """Valid inputs of each target, to start the fuzzers from (built once, not stored)."""
    return list(_seeds(name))


def _store_seeds() -> dict[str, list[bytes]]:
    import cclogfs

    with tempfile.TemporaryDirectory(dir=SCRATCH) as tmp:
        path = Path(tmp, "s")
        with cclogfs.open_store(path, create=True, segment_records=4, codec="columnar") as store:
            for i in range(6):
                store.put_window("/odom" if i % 2 else "/tf", [(i * 10 + k, json.dumps({"x": k * 0.5, "i": i}))
                                                              for k in range(3)], meta={"i": i})  # fmt: skip
        files = {p.name: p.read_bytes() for p in path.iterdir() if p.is_file()}
    seg = files["00000000000000000000.seg"]
    first_len = struct.unpack_from("<I", seg, 32 + 8)[0] + struct.unpack_from("<Q", seg, 32 + 58)[0]
    idx = next(v for k, v in files.items() if k.endswith(".idx"))
    body = files["MANIFEST"][fmt.MANIFEST_HEADER.size : -4]
    return {"record_header": [seg[32 : 32 + first_len]], "segment_scan": [seg], "index": [idx],
            "manifest": [files["MANIFEST"]], "manifest_json": [body]}  # fmt: skip


def _codec_seed() -> list[bytes]:
    from cclogfs.codecs import codec_from_config
    from cclogfs.codecs.base import frame

    stamps, texts = [1, 2, 3], ['{"a":1.5,"b":[1,2]}', '{"a":2.5,"b":[1,3]}', '{"a":-1,"b":[]}']
    raw_len = len(frame(stamps, texts))
    return [bytes([i]) + struct.pack("<II", 3, raw_len) + codec_from_config(c).encode(stamps, texts)
            for i, c in enumerate(("none", "zstd", "lzma", "columnar"))]  # fmt: skip


_SEEDS: dict[str, Callable[[], list[bytes]]] = {
    **{k: (lambda k=k: _store_seeds()[k]) for k in ("record_header", "segment_scan", "index", "manifest",
                                                     "manifest_json")},  # fmt: skip
    "codec_payload": _codec_seed,
    "record_config_meta": lambda: [b'{"id":"zstd","level":3}\0{"i":1}', b'{"id":"columnar","version":1}\0{}'],
    "jsonl_line": lambda: [b'{"topic":"/odom","stamp_ns":5,"msg":{"a":1}}', b'{"t":1.5,"topic":"/a","msg":[]}'],
    "jsonl_split": lambda: [b'{"topic": "/odom", "stamp_ns": 5, "msg": {"a": [1.5, -2e-3, true, null], "s": "\xc3\xa9\\n"}}\n'
                            b'{"topic": "/tf", "stamp_ns": -7, "msg": {"b": {"c": "\\u00e9"}, "d": []}}\r\n'],
    "aging_policy": lambda: [b'{"pose":{"x":1.23456,"y":[1e-3,2]}}'],
    "model_files": lambda: [b'{"format":"x"}\0'],
    "rosbag1": lambda: [b""],
}
