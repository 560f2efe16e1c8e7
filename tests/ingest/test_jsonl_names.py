"""A JSONL topic the store cannot take as a stream name (a control character, escaped or
raw; over 1024 bytes) is a bad line, named by its line and skipped with --on-error skip,
not a store error at the window's flush that names no line and stops even a skipping run
(found by attack: /tmp/atk3/mk_odd.py). Both parse paths (split_path fixture)."""

from __future__ import annotations

import pytest

from cclogfs import open_store
from cclogfs.cli import main
from cclogfs.errors import SourceError
from cclogfs.ingest import JsonlSource
from cclogfs.jsontext.check import NAME_MAX_BYTES
from cclogfs.store.format import MAX_NAME

pytestmark = pytest.mark.usefixtures("split_path")

BAD = ['"/x\\ny"', '"/nul\\u0000x"', '"/a\u0085b"', '"/del\u007f"', '"/' + "l" * 1100 + '"']


def lines(topics):
    return "".join(f'{{"topic": {t}, "stamp_ns": {i}, "msg": {{"i": {i}}}}}\n' for i, t in enumerate(topics))


def test_name_limit_is_the_stores():
    assert NAME_MAX_BYTES == MAX_NAME


@pytest.mark.parametrize("topic", BAD)
def test_bad_topic_stops_naming_its_line(tmp_path, topic):
    path = tmp_path / "log.jsonl"
    path.write_text(lines(['"/ok"', topic, '"/ok"']), encoding="utf-8")
    with JsonlSource(path) as src, pytest.raises(SourceError, match=r"line 2: 'topic' "):
        list(src)


def test_bad_topics_are_skipped_and_the_rest_recorded(tmp_path, capsys):
    path = tmp_path / "log.jsonl"
    topics = ['"/ok"', *BAD, '"/ok"'] * 3
    path.write_text(lines(topics), encoding="utf-8")
    store = tmp_path / "s"
    assert main(["record", str(path), "--store", str(store), "--on-error", "skip"]) == 4  # lines left out: exit 4
    err = capsys.readouterr().err
    assert err.count("'topic' contains the control character") == 12
    assert err.count("over the 1024-byte limit") == 3
    # Found by attack: the summary said only 'N messages in, N kept' (exit 0) however many
    # lines were skipped; now it counts them too.
    assert f"{path}: 15 bad lines skipped (--on-error skip), not recorded" in err, err
    with open_store(store, readonly=True) as s:
        kept = [stamp for w in s.query("/ok") for stamp, _ in w.messages()]
    assert kept == [i for i, t in enumerate(topics) if t == '"/ok"']
