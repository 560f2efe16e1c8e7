"""cclogfs.codecs.columnar_format mirrors docs/CODEC_COLUMNAR.md: the numbers in code and in
the document must agree, since readers elsewhere implement the document."""

import re
from pathlib import Path

from cclogfs.codecs import columnar_format as f

DOC = (Path(__file__).parents[2] / "docs" / "CODEC_COLUMNAR.md").read_text()


def test_every_column_kind_has_the_documented_number():
    table = {name: int(value) for name, value in re.findall(r"^\| ([A-Z_0-9]+) \| (\d+) \|", DOC, re.M)}
    assert table == {kind.name: kind.value for kind in f.ColumnKind}


def test_kinds_per_version_match_the_document():
    assert set(f.VERSION_KINDS) == set(f.FORMAT_VERSIONS) and f.LATEST_VERSION == max(f.FORMAT_VERSIONS)
    K = f.ColumnKind
    assert f.VERSION_KINDS[1] == set(range(1, 8))
    assert f.VERSION_KINDS[2] == set(range(1, 9))
    assert f.VERSION_KINDS[3] == set(range(1, 11)) - {K.FLOAT, K.INT_PACKED}
    assert f.VERSION_KINDS[4] == f.VERSION_KINDS[3] | {K.DECIMAL}
    assert "v1 holds kinds 1-7, v2 kinds 1-8, v3 kinds 1-10 except FLOAT (4)" in " ".join(DOC.split())


def test_struct_sizes_are_the_documented_field_widths():
    assert f.HEADER.size == 1 + 4 + 4  # u8 version | u32 body_len | u32 xxh32
    assert f.GROUP_HEADER.size == 4 + 4  # u32 n | u32 k
    assert f.PACKED_HEADER.size == 8 + 8 + 1  # i64 first | u64 step | u8 width
    assert f.OFFSET_HEADER.size == 8 + 8 + 8 + 1  # i64 first | u64 step | i64 base | u8 width
    assert f.RAW_GROUP == 0xFFFF and "0xFFFF" in DOC and f.MAX_GROUPS < f.RAW_GROUP


def test_decimal_limits_match_the_document():
    assert list(f.DECIMAL_DIGITS) == list(range(1, 19)) and "d in 1..18" in DOC
    assert f.FLOAT_ORDERS == f.DECIMAL_ORDERS == (1, 2, 3) and "r in {1, 2, 3}" in DOC
