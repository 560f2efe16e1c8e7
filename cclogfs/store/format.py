"""Mirror of docs/FORMAT.md: every number the on-disk format defines lives here.

This module knows the *physical* layout only: how to build and check the bytes of a
record header, a segment header, an index and the manifest. What the records mean is the
store's business.
"""

from __future__ import annotations

import json
import re
import struct
from dataclasses import dataclass
from enum import IntEnum, IntFlag

import crcmod.predefined
import xxhash

from . import planted

# The manifest's `format_version`: 1 for a store never compacted (byte for byte what version 1
# wrote), 2 once records were rewritten or segments dropped, 3 once a writer of this version
# wrote to it (records carry their synced length; the manifest a checkpoint and the damage
# found). Readers accept all three.
FORMAT_VERSION = 3
COMPACTED_FORMAT_VERSION = 2
FORMAT_VERSIONS = (1, 2, 3)
# The `version` field of the segment, index and manifest file headers: their layouts did not
# change in format version 2.
FILE_VERSION = 1

# Times are signed 64-bit nanoseconds (FORMAT.md).
MIN_NS, MAX_NS = -(1 << 63), (1 << 63) - 1

# -- checksums -----------------------------------------------------------------------------

# A test switch, empty in use: file kinds ("record", "index", "manifest", "segment header")
# whose checksums are not verified, so that a fuzzer's random bytes reach the parsing past
# them (tests/fuzz). Nothing outside the tests adds to it.
CHECKSUMS_OFF: set[str] = set()

_crc32c_fn = crcmod.predefined.mkPredefinedCrcFun("crc-32c")


def crc32c(data: bytes | memoryview) -> int:
    return _crc32c_fn(data)


def xxh3(data: bytes | memoryview) -> int:
    return xxhash.xxh3_64_intdigest(data)


# -- enums ---------------------------------------------------------------------------------


class RecordKind(IntEnum):
    """Record kinds. 0 is invalid; values never change."""

    WINDOW = 1


class RecordFlag(IntFlag):
    """Record flag bits. Values never change; a bit not listed here is skipped and reported."""

    AGED = 1  # the texts are not byte-exact what was put; meta key "aged" says how they differ
    PART = 2  # this window continues in the next record (seq + 1): every part of a split window but its last


KNOWN_FLAGS = int(RecordFlag.AGED | RecordFlag.PART)
AGED_META_KEY = "aged"


class Reason:
    """The fixed set of reasons a record or file is rejected (LevelDB-style reporting).

    Each names one kind of damage; docs/FORMAT.md ("Reject reasons") lists where each occurs.
    """

    TORN = "torn record"
    ZERO_FILL = "zero fill"
    BAD_MAGIC = "bad magic"
    BAD_LENGTH = "bad record length"
    BAD_FIELD = "bad record field"
    HEADER_CRC = "header checksum mismatch"
    PAYLOAD_HASH = "payload checksum mismatch"
    SEQ_GAP = "sequence gap"
    UNKNOWN_KIND = "unknown record kind"
    UNSUPPORTED_VERSION = "unsupported record version"
    UNKNOWN_FLAGS = "unknown record flags"
    UNFINISHED_PUT = "unfinished put"
    BAD_SEGMENT_HEADER = "bad segment header"
    DROPPED_SEGMENT = "segment after the torn tail"
    CODEC_MISMATCH = "codec mismatch"
    INDEX_MISMATCH = "index does not match its segment"
    SIZE_MISMATCH = "sealed segment size differs from the manifest"
    MISSING_SEGMENT = "missing segment"
    STRAY_SEGMENT = "stray segment"
    ROLLED_BACK = "manifest older than its segments"


# -- limits --------------------------------------------------------------------------------

MAX_NAME = 1024
MAX_CONFIG = 4096
MAX_META = 65536
MAX_COUNT = 1 << 24
MAX_RAW = 256 << 20  # the framing limit: records older versions wrote up to it are still framed
ENC_SLACK = 64 << 10  # what a codec may add to an incompressible window
MAX_ENC = MAX_RAW + ENC_SLACK
# What one record this version writes holds at most (put_window splits a larger window into
# consecutive records), and what a read decodes at most: the memory decoding one record costs
# is a multiple of it (FORMAT.md, "Limits"), 16 MiB being 90 times the largest window `cclog
# record` cuts from the real runs of ../shared/data. A deployment that must read records an
# older version wrote above it raises DECODE_RAW_LIMIT (at most MAX_RAW), and its bound with it.
MAX_RECORD_RAW = 16 << 20
# The longest message text a record holds: the message alone, after the window's count (4
# bytes) and its stamp and length (12). A source told this names the line of a longer one.
MAX_MESSAGE_TEXT = MAX_RECORD_RAW - 16
DECODE_RAW_LIMIT = MAX_RECORD_RAW
MAX_MANIFEST = 64 << 20
# The smallest record: the fixed header, an empty name (a skipped record of another kind may
# have one) and the header CRC. Bounds how many records a segment of a given size can hold.
MIN_RECORD = 74 + 4


# -- file names ----------------------------------------------------------------------------

MANIFEST = "MANIFEST"
LOCK = "LOCK"
RESERVE = "RESERVE"
# Space the writer sets aside so that retention can relieve a full disk (FORMAT.md,
# "Reserve"): what opening and one drop write, with room to spare.
RESERVE_BASE = 1 << 20
RESERVE_STEP = 64 << 10


def reserve_bytes(manifest_len: int) -> int:
    """Size of the RESERVE file for a MANIFEST of `manifest_len` bytes: 1 MiB (a lock, a
    new active segment, the index of a segment sealed on open) plus twice the manifest (its
    temporary copy beside it), rounded up to 64 KiB."""
    need = RESERVE_BASE + 2 * manifest_len
    return -(-need // RESERVE_STEP) * RESERVE_STEP
TMP_SUFFIX = ".tmp"
SEGMENT_SUFFIX = ".seg"
INDEX_SUFFIX = ".idx"
QUARANTINE = "quarantine"  # directory of bytes cut from the log, named by the manifest
# Bytes recovery cut from a segment's tail (FORMAT.md, "Durability contract").
SIDE_FILE = re.compile(r"^\d{20}(?:-\d+)?\.seg\.tail-\d+$")
_SEQ_NAME = re.compile(r"^(\d{20})(?:-([1-9]\d{0,9}))?\.(seg|idx)$")


def _gen_part(gen: int) -> str:
    # Generation 0 keeps the version 1 names, so a store never rewritten is unchanged.
    return f"-{gen}" if gen else ""


def segment_name(first_seq: int, gen: int = 0) -> str:
    return f"{first_seq:020d}{_gen_part(gen)}{SEGMENT_SUFFIX}"


def index_name(first_seq: int, gen: int = 0) -> str:
    return f"{first_seq:020d}{_gen_part(gen)}{INDEX_SUFFIX}"


def parse_seq_name(name: str) -> tuple[int, str, int] | None:
    """(first_seq, "seg" | "idx", generation) for a segment or index file name, else None."""
    m = _SEQ_NAME.match(name)
    return (int(m.group(1)), m.group(3), int(m.group(2) or 0)) if m else None


# -- segment header ------------------------------------------------------------------------

SEGMENT_MAGIC = b"CCLS"
SEGMENT_HEADER = struct.Struct("<4sHHQqI")  # magic, version, flags, first_seq, created_ns, reserved
SEGMENT_HEADER_SIZE = SEGMENT_HEADER.size + 4  # + crc


def pack_segment_header(first_seq: int, created_ns: int, manifest_gen: int = 0) -> bytes:
    """`manifest_gen`: the manifest generation the file was made under (format 3; 0 before)."""
    body = SEGMENT_HEADER.pack(SEGMENT_MAGIC, FILE_VERSION, 0, first_seq, created_ns, manifest_gen)
    return body + struct.pack("<I", crc32c(body))


def segment_manifest_gen(data: bytes) -> int:
    """The manifest generation an intact segment header states (0 when damaged or older)."""
    if unpack_segment_header(data) is None:
        return 0
    return SEGMENT_HEADER.unpack_from(data)[5]


def segment_header_fault(data: bytes, first_seq: int) -> str:
    """What is wrong with a segment header, in plain words naming each field (offsets in
    the file); "" when it is intact and states `first_seq` (the file name's)."""
    if len(data) < SEGMENT_HEADER_SIZE:
        return f"the {SEGMENT_HEADER_SIZE}-byte segment header is cut short to {len(data)} bytes"
    magic, version, flags, stated, _created_ns, _gen = SEGMENT_HEADER.unpack_from(data)
    faults = []
    if magic != SEGMENT_MAGIC:
        faults.append(f"magic (bytes 0-3) is {magic!r}, not {SEGMENT_MAGIC!r}")
    if version != FILE_VERSION:
        faults.append(f"version (bytes 4-5) is {version}, not {FILE_VERSION}")
    if flags != 0:
        faults.append(f"flags (bytes 6-7) is {flags}, not 0")
    if stated != first_seq:
        faults.append(f"first_seq (bytes 8-15) is {stated}, the file name says {first_seq}")
    if struct.unpack_from("<I", data, SEGMENT_HEADER.size)[0] != crc32c(data[: SEGMENT_HEADER.size]):
        # With the fields above as they should be, the changed bits are in one that has no
        # expected value: created_ns (16-23), manifest_gen (24-27) or the CRC itself.
        faults.append("its CRC (bytes 28-31) does not match bytes 0-27" if faults else
                      "its CRC (bytes 28-31) does not match bytes 0-27: created_ns (16-23), "
                      "manifest_gen (24-27) or the CRC changed")  # fmt: skip
    return "; ".join(faults)


def unpack_segment_header(data: bytes) -> tuple[int, int] | None:
    """(first_seq, created_ns), or None when the header is torn or damaged."""
    if len(data) < SEGMENT_HEADER_SIZE:
        return None
    body = data[: SEGMENT_HEADER.size]
    (crc,) = struct.unpack_from("<I", data, SEGMENT_HEADER.size)
    magic, version, _flags, first_seq, created_ns, _ = SEGMENT_HEADER.unpack(body)
    if magic != SEGMENT_MAGIC or version != FILE_VERSION:
        return None
    if crc != crc32c(body) and "segment header" not in CHECKSUMS_OFF:
        return None
    return first_seq, created_ns


# -- record --------------------------------------------------------------------------------

RECORD_MAGIC = b"CCLR"
# Version 1: no synced length; version 2 appends `synced_len` (u64) after `meta`.
RECORD_VERSION = 2
RECORD_VERSIONS = (1, 2)
SYNCED = struct.Struct("<Q")
# magic kind version flags header_len seq start end count codec name_len config_len meta_len
# raw_len enc_len payload_xxh3
RECORD_FIXED = struct.Struct("<4sBBHIQqqIHHHIQQQ")
RECORD_FIXED_SIZE = RECORD_FIXED.size  # 74
MAX_HEADER = RECORD_FIXED_SIZE + MAX_NAME + MAX_CONFIG + MAX_META + SYNCED.size + 4


@dataclass(frozen=True, slots=True)
class RecordHeader:
    """A record header as it is on disk (fields of the table in FORMAT.md)."""

    kind: int
    version: int
    flags: int
    header_len: int
    seq: int
    start_ns: int
    end_ns: int
    count: int
    codec: int
    name: str
    config: bytes
    meta: bytes
    raw_len: int
    enc_len: int
    payload_xxh3: int
    synced: int = 0  # version 2: segment bytes made durable by the last sync before this record

    @property
    def record_len(self) -> int:
        return self.header_len + self.enc_len


def pack_record(
    *,
    seq: int,
    start_ns: int,
    end_ns: int,
    count: int,
    codec: int,
    name: bytes,
    config: bytes,
    meta: bytes,
    raw_len: int,
    payload: bytes,
    kind: int = RecordKind.WINDOW,
    flags: int = 0,
    synced: int | None = None,
) -> bytes:
    """The bytes of one record. Callers have validated every field against the limits.
    `synced` None writes record version 1 (no synced length), else version 2."""
    tail = b"" if synced is None else SYNCED.pack(synced)
    version = 1 if synced is None else RECORD_VERSION
    header_len = RECORD_FIXED_SIZE + len(name) + len(config) + len(meta) + len(tail) + 4
    fixed = RECORD_FIXED.pack(
        RECORD_MAGIC, kind, version, flags, header_len, seq, start_ns, end_ns, count,
        codec, len(name), len(config), len(meta), raw_len, len(payload), xxh3(payload),
    )  # fmt: skip
    head = b"".join((fixed, name, config, meta, tail))
    return b"".join((head, struct.pack("<I", crc32c(head)), payload))


class RecordError(Exception):
    """A record fails a physical check; `reason` is a `Reason` string, `offset` where the
    record starts in its file (-1 when not known where the check ran)."""

    def __init__(self, reason: str, detail: str = "", offset: int = -1):
        super().__init__(f"{reason}{': ' + detail if detail else ''}")
        self.reason = reason
        self.offset = offset


# Header bytes each known record version adds after `meta`.
_EXTRA = {1: 0, 2: SYNCED.size}


def check_fixed(fixed: bytes, available: int) -> int:
    """Check a record's fixed header before trusting it; return header_len.

    `available` is how many bytes the file holds from the record's start. Raises
    RecordError with the reason (torn, zero fill, bad magic, bad length).
    """
    if len(fixed) < RECORD_FIXED_SIZE:
        if not fixed.strip(b"\0"):
            raise RecordError(Reason.ZERO_FILL)
        raise RecordError(Reason.TORN, f"{len(fixed)} of {RECORD_FIXED_SIZE} header bytes")
    if fixed[:4] != RECORD_MAGIC:
        if not fixed.strip(b"\0"):
            raise RecordError(Reason.ZERO_FILL)
        raise RecordError(Reason.BAD_MAGIC, repr(fixed[:4]))
    (_m, _k, version, _f, header_len, _s, _a, _b, count, _c, name_len, config_len, meta_len,
     raw_len, enc_len, _h) = RECORD_FIXED.unpack_from(fixed)  # fmt: skip
    if "trust-length" in planted.BUGS:
        return header_len
    least = RECORD_FIXED_SIZE + name_len + config_len + meta_len + 4
    # A newer version may append header fields (FORMAT.md, extension rules): frame it by
    # header_len so that it can be skipped, not mistaken for the end of the log.
    if (
        name_len > MAX_NAME
        or config_len > MAX_CONFIG
        or meta_len > MAX_META
        or (header_len != least + _EXTRA[version] if version in _EXTRA else not least <= header_len <= MAX_HEADER)
        or count > MAX_COUNT
        or raw_len > MAX_RAW
        or enc_len > MAX_ENC
    ):
        raise RecordError(Reason.BAD_LENGTH, f"header_len={header_len} enc_len={enc_len}")
    if available < header_len + enc_len:
        raise RecordError(Reason.TORN, f"{available} of {header_len + enc_len} bytes present")
    return header_len


def parse_header(head: bytes) -> RecordHeader:
    """Parse and CRC-check a whole header (`check_fixed` already passed on it)."""
    (magic, kind, version, flags, header_len, seq, start_ns, end_ns, count, codec, name_len,
     config_len, meta_len, raw_len, enc_len, payload_xxh3) = RECORD_FIXED.unpack_from(head)  # fmt: skip
    (crc,) = struct.unpack_from("<I", head, header_len - 4)
    if crc != crc32c(memoryview(head)[: header_len - 4]) and "record" not in CHECKSUMS_OFF:
        raise RecordError(Reason.HEADER_CRC)
    pos = RECORD_FIXED_SIZE
    try:
        name = head[pos : pos + name_len].decode("utf-8")
    except UnicodeDecodeError as err:
        raise RecordError(Reason.BAD_FIELD, "stream name is not UTF-8") from err
    pos += name_len
    config = head[pos : pos + config_len]
    meta = head[pos + config_len : pos + config_len + meta_len]
    synced = SYNCED.unpack_from(head, header_len - 12)[0] if version == 2 else 0
    return RecordHeader(
        kind, version, flags, header_len, seq, start_ns, end_ns, count, codec, name,
        bytes(config), bytes(meta), raw_len, enc_len, payload_xxh3, synced,
    )  # fmt: skip


def check_fields(header: RecordHeader) -> str | None:
    """Why an intact record cannot be used as it is, or None.

    RecordError for fields no writer may produce (kind 0, an empty window, time running
    backwards, a bad stream name); the reason string for what a newer writer may produce
    and a reader skips (another kind, version or flags).
    """
    if header.kind == 0:
        raise RecordError(Reason.BAD_FIELD, "kind 0 is invalid")
    if header.kind != RecordKind.WINDOW:
        return Reason.UNKNOWN_KIND
    if header.version not in RECORD_VERSIONS:
        return Reason.UNSUPPORTED_VERSION
    if header.flags & ~KNOWN_FLAGS:
        return Reason.UNKNOWN_FLAGS
    if header.count < 1 or header.end_ns < header.start_ns:
        raise RecordError(Reason.BAD_FIELD, f"count {header.count}, {header.start_ns}..{header.end_ns}")
    if not header.name or any(ord(c) < 32 or 127 <= ord(c) < 160 for c in header.name):
        raise RecordError(Reason.BAD_FIELD, f"stream name {header.name!r}")
    return None


def check_payload(header: RecordHeader, payload: bytes | memoryview) -> None:
    if len(payload) != header.enc_len:
        raise RecordError(Reason.TORN, f"{len(payload)} of {header.enc_len} payload bytes")
    if xxh3(payload) != header.payload_xxh3 and "record" not in CHECKSUMS_OFF:
        raise RecordError(Reason.PAYLOAD_HASH)


# -- time index ----------------------------------------------------------------------------

INDEX_MAGIC = b"CCLI"
INDEX_HEADER = struct.Struct("<4sHHQQII")  # magic version flags first_seq segment_size count names_len
# One entry per record; the layout mirrors the table in FORMAT.md.
INDEX_ENTRY_FIELDS = [
    ("stream", "<u4"),
    ("count", "<u4"),
    ("seq", "<u8"),
    ("start", "<i8"),
    ("end", "<i8"),
    ("offset", "<u8"),
    ("length", "<u8"),
    ("raw_len", "<u8"),
]
INDEX_ENTRY = struct.Struct("<" + "".join({"<u4": "I", "<u8": "Q", "<i8": "q"}[t] for _, t in INDEX_ENTRY_FIELDS))

# -- manifest ------------------------------------------------------------------------------

MANIFEST_MAGIC = b"CCLM"
MANIFEST_HEADER = struct.Struct("<4sHHI")  # magic version flags body_len


def pack_manifest(body: dict) -> bytes:
    text = json.dumps(body, separators=(",", ":"), sort_keys=True).encode()
    head = MANIFEST_HEADER.pack(MANIFEST_MAGIC, FILE_VERSION, 0, len(text)) + text
    return head + struct.pack("<I", crc32c(head))


def unpack_manifest(data: bytes) -> dict:
    """The manifest body; raises RecordError with a reason when the bytes are damaged."""
    if len(data) < MANIFEST_HEADER.size + 4:
        raise RecordError(Reason.TORN, f"{len(data)} bytes")
    magic, version, _flags, body_len = MANIFEST_HEADER.unpack_from(data)
    if magic != MANIFEST_MAGIC:
        raise RecordError(Reason.BAD_MAGIC, repr(magic))
    if version != FILE_VERSION:
        raise RecordError(Reason.UNSUPPORTED_VERSION, f"version {version}")
    if body_len > MAX_MANIFEST or len(data) != MANIFEST_HEADER.size + body_len + 4:
        raise RecordError(Reason.BAD_LENGTH, f"body_len={body_len}, file is {len(data)} bytes")
    end = MANIFEST_HEADER.size + body_len
    (crc,) = struct.unpack_from("<I", data, end)
    if crc != crc32c(data[:end]) and "manifest" not in CHECKSUMS_OFF:
        raise RecordError(Reason.HEADER_CRC)
    try:
        return json.loads(data[MANIFEST_HEADER.size : end])
    except (ValueError, RecursionError) as err:  # UnicodeDecodeError is a ValueError
        raise RecordError(Reason.BAD_FIELD, f"body is not JSON: {str(err)[:80]}") from None


def manifest_size_limit() -> int:
    """Largest MANIFEST file: checked on its size before it is read (FORMAT.md)."""
    return MANIFEST_HEADER.size + MAX_MANIFEST + 4


def index_size_limit(segment_size: int) -> int:
    """Largest `.idx` a segment of `segment_size` bytes can have (FORMAT.md, "Time index"):
    one 56-byte entry per record of at least MIN_RECORD bytes, and a names list whose JSON
    is at most 3 bytes per name byte and 4 per name (each name is in one of the records)."""
    body = max(0, segment_size - SEGMENT_HEADER_SIZE)
    return INDEX_HEADER.size + 56 * (body // MIN_RECORD) + 3 * body + 2 + 8
