"""A message nested as deep as the store takes (Python's json reads ~900 levels) exports
to MCAP and reads back byte for byte; its JSON Schema describes the first 64 levels
(`{}`, any JSON, below). Before, the schema's recursion ended in a RecursionError
traceback (found by the attack of l-atk6)."""

import cclogfs
from cclogfs.cli import main
from cclogfs.export.jsonschema import MAX_DEPTH, schema_of


def nested(levels: int) -> str:
    return '{"n": ' * levels + "1.5" + "}" * levels


def test_a_deep_message_exports_and_converts_back(tmp_path, capsys):
    text = nested(900)
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/deep", [(1, text), (2, '{"n": 2}')])
    assert main(["export", str(tmp_path / "s"), "--mcap", str(tmp_path / "o.mcap")]) == 0
    capsys.readouterr()
    assert main(["cat", str(tmp_path / "s")]) == 0
    cat = capsys.readouterr().out
    assert main(["convert", str(tmp_path / "o.mcap"), "-o", "-"]) == 0
    assert capsys.readouterr().out == cat and text in cat


def test_the_schema_stops_describing_at_max_depth():
    import json

    schema = schema_of(json.loads(nested(MAX_DEPTH + 10)))
    depth = 0
    while schema:
        schema = schema["properties"]["n"]
        depth += 1
    assert depth == MAX_DEPTH
