"""The optional compiled helpers (issue 14); everything else is in pyproject.toml.
`optional=True`: without a C compiler the install still succeeds, and cclogfs takes the
pure-Python paths, which give the same results: the columnar encoder's row finder
(cclogfs/codecs/shapes.py, same bytes) and the JSONL splitter (cclogfs/ingest/jsonl.py,
same messages and errors)."""

from setuptools import Extension, setup

setup(ext_modules=[
    Extension("cclogfs.codecs._rows", ["cclogfs/codecs/_rows.c"], optional=True),
    Extension("cclogfs.ingest._jsonl_split", ["cclogfs/ingest/_jsonl_split.c"], optional=True),
])
