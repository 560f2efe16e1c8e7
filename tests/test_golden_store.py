"""The committed store of format version 1 must read the same forever."""

import json
import shutil
from pathlib import Path

import cclogfs
from cclogfs.format import pack_record, CodecId

GOLDEN = Path(__file__).parent / "golden"


def test_golden_store_reads_back(tmp_path):
    expected = json.loads((GOLDEN / "store_v1.expected.json").read_text())
    shutil.copytree(GOLDEN / "store_v1", tmp_path / "s")
    for opts in ({"readonly": True}, {}):
        with cclogfs.open_store(tmp_path / "s", **opts) as store:
            assert store.recovery.clean
            got = sorted(store.query(), key=lambda w: w.seq)
            assert [
                {"seq": w.seq, "name": w.name, "meta": w.meta, "messages": [list(m) for m in w.messages()]}
                for w in got
            ] == expected
            assert len(store.sealed) >= 1  # the golden store has sealed segments and an index


def test_record_bytes_are_pinned():
    # The "none" record of /tf is stored verbatim: today's encoder must produce the same bytes.
    from cclogfs.codecs import frame

    data = (GOLDEN / "store_v1" / "00000000000000000001.seg").read_bytes()
    texts = [b'{"a" :1.0, "b":[ ]}', b' "\\u00e9" ']
    raw = frame([1_000_000_000, 1_000_000_001], texts)
    record = pack_record(seq=2, start_ns=1_000_000_000, end_ns=1_000_000_001, count=2, codec=CodecId.NONE,
                         name=b"/tf", config=b'{"id":"none"}', meta=b"{}", raw_len=len(raw), payload=raw)  # fmt: skip
    assert record in data
