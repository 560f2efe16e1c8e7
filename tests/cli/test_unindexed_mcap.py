"""l-left8: an MCAP file whose chunks have no message indexes (the `mcap` Writer without
IndexType.MESSAGE) had those chunks' messages left out by record and convert: rosbags
counts a chunk's channels from its message indexes, so such a chunk looked empty. With
every chunk unindexed the run failed with "yielded no message"; with only the later chunks
unindexed it stored 3,996 of nav2_turtlebot's 8,197 messages with exit 0."""

import pytest
from mcap.reader import make_reader
from mcap.writer import IndexType, Writer

from cclogfs.cli import main

NAV2 = "nav2_turtlebot.mcap"  # 8,197 messages, CDR


def rewrite(src, dst, *, unindexed_from: int) -> list:
    """`src`'s messages written to `dst` in 64 KiB chunks, those from message
    `unindexed_from` on in chunks without message indexes; the chunk indexes written."""
    with open(src, "rb") as f, open(dst, "wb") as out:
        w = Writer(out, chunk_size=64 * 1024)
        w.start(profile="ros2", library="test")
        schemas, channels = {}, {}
        for n, (schema, ch, m) in enumerate(make_reader(f).iter_messages(log_time_order=False)):
            if n == unindexed_from:  # the Writer has no public switch mid-file: a writer that changed its mind
                w._Writer__index_types = IndexType.ALL & ~IndexType.MESSAGE
            if ch.id not in channels:
                if schema.id not in schemas:
                    schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
                channels[ch.id] = w.register_channel(ch.topic, ch.message_encoding, schemas[schema.id], ch.metadata)
            w.add_message(channels[ch.id], m.log_time, m.data, m.publish_time, m.sequence)
        w.finish()
    with open(dst, "rb") as f:
        return make_reader(f).get_summary().chunk_indexes


def cat(store, capsys) -> list[str]:
    capsys.readouterr()
    assert main(["cat", str(store)]) == 0
    return capsys.readouterr().out.splitlines()


@pytest.mark.parametrize("unindexed_from", [0, 4000])
def test_chunks_without_message_indexes_are_read_whole(shared_data, tmp_path, capsys, unindexed_from):
    chunks = rewrite(shared_data(NAV2), tmp_path / "x.mcap", unindexed_from=unindexed_from)
    assert any(not c.message_index_offsets for c in chunks)
    assert main(["record", str(tmp_path / "x.mcap"), "--store", str(tmp_path / "s")]) == 0
    assert main(["record", str(shared_data(NAV2)), "--store", str(tmp_path / "whole")]) == 0
    assert cat(tmp_path / "s", capsys) == cat(tmp_path / "whole", capsys)  # all 8,197, byte for byte
    assert main(["convert", str(tmp_path / "x.mcap"), "-o", str(tmp_path / "x.jsonl")]) == 0
    assert len((tmp_path / "x.jsonl").read_text().splitlines()) == 8197


def test_a_damaged_unindexed_chunk_is_named(shared_data, tmp_path, capsys):
    chunks = rewrite(shared_data(NAV2), tmp_path / "x.mcap", unindexed_from=0)
    data = bytearray((tmp_path / "x.mcap").read_bytes())
    chunk = chunks[2]
    data[chunk.chunk_start_offset + chunk.chunk_length // 2] ^= 0xFF
    (tmp_path / "bad.mcap").write_bytes(bytes(data))
    capsys.readouterr()
    assert main(["record", str(tmp_path / "bad.mcap"), "--store", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err
    assert f"the chunk at byte {chunk.chunk_start_offset:,} (messages not counted, as it has no message index" in err
    assert "Traceback" not in err
