"""The columnar encoder's two ways to find a shape's value rows: the compiled helper
(cclogfs/codecs/_rows.c, built by setup.py when a C compiler is there) and the re module.
Tests marked with the `row_path` fixture run once per way; both must give the same bytes."""

import pytest

from cclogfs.codecs import shapes

COMPILED = shapes._match_rows_c


@pytest.fixture(scope="module", params=["compiled", "python"])
def row_path(request):
    if request.param == "compiled" and COMPILED is None:
        pytest.skip("the compiled helper cclogfs.codecs._rows is not built (no C compiler at install)")
    shapes._match_rows_c = COMPILED if request.param == "compiled" else None
    yield request.param
    shapes._match_rows_c = COMPILED
