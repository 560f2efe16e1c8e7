"""A file output (`convert -o`, `export --mcap`), a directory output (`export --parquet`,
`--rosbag2`) and a new store (`record --store`) are never inside another store: `convert -o
STORE/odom.jsonl` wrote among the segments (fsck warned of it ever after), and an output
named like a segment (`STORE/00000000000000000099.seg`) was taken by the store's next writer
for a torn tail and deleted; `record --store STORE/sub` made a store inside a store; each
exit 0 (found by the attack of l-atk8)."""

import pytest

from cclogfs.cli import main
from cclogfs.jsontext.lines import format_line


def listing(path):
    return sorted((p.relative_to(path).as_posix(), p.stat().st_size) for p in path.rglob("*"))


@pytest.fixture()
def stores(tmp_path):
    src = tmp_path / "in.jsonl"
    src.write_text("".join(format_line("/a", i, f'{{"i": {i}}}') for i in range(20)))
    for name in ("s", "other"):
        assert main(["record", str(src), "--store", str(tmp_path / name), "--append"]) == 0
    return src, tmp_path / "s", tmp_path / "other"


@pytest.mark.parametrize("name", ["odom.jsonl", "00000000000000000099.seg"])
def test_convert_refuses_an_output_inside_a_store(stores, capsys, name):
    src, store, _ = stores
    before = listing(store)
    for extra in ([], ["--force"]):
        assert main(["convert", str(src), "-o", str(store / name), *extra]) == 1
        assert "is a cclogfs store" in capsys.readouterr().err
    assert listing(store) == before


@pytest.mark.parametrize("flag, name", [("--mcap", "x.mcap"), ("--parquet", "lake"), ("--rosbag2", "bag")])
def test_export_refuses_an_output_inside_another_store(stores, capsys, flag, name):
    _, store, other = stores
    before = listing(other)
    assert main(["export", str(store), flag, str(other / name)]) == 1
    assert "is a cclogfs store" in capsys.readouterr().err
    assert listing(other) == before


def test_record_refuses_a_store_inside_a_store(stores, capsys):
    src, store, _ = stores
    before = listing(store)
    assert main(["record", str(src), "--store", str(store / "sub"), "--append"]) == 1
    assert "is a cclogfs store" in capsys.readouterr().err
    assert listing(store) == before
    # the store itself is no store inside a store: recording into it again works
    assert main(["record", str(src), "--store", str(store), "--append"]) == 0
