"""A JSON Lines file saved with a UTF-8 byte order mark (as some Windows editors do) is named
as such, not "of an unknown file type" (found by the attack of l-atk6)."""

from cclogfs.cli import main


def test_a_bom_is_named(tmp_path, capsys):
    src = tmp_path / "log.jsonl"
    src.write_bytes(b'\xef\xbb\xbf{"topic": "/a", "stamp_ns": 1, "msg": {"x": 1}}\n')
    for cmd in (["convert", str(src), "-o", "-"], ["record", str(src), "--store", str(tmp_path / "s")]):
        assert main(cmd) == 1
        err = capsys.readouterr().err
        assert "starts with a UTF-8 byte order mark" in err and "unknown file type" not in err
    assert not (tmp_path / "s").exists()
