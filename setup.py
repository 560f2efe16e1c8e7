"""The optional compiled helpers (issue 14); everything else is in pyproject.toml.
`optional=True`: without a C compiler the install still succeeds, and cclogfs takes the
pure-Python paths, which give the same results: the columnar encoder's row finder
(cclogfs/codecs/shapes.py, same bytes), the byte planes of packed integers and float
deltas (cclogfs/codecs/columns.py, same bytes), the JSONL splitter (cclogfs/ingest/jsonl.py, same
messages and errors), and the classifier's odometry reader and live feature stream
(cclogfs/classifier/features.py, same values)."""

from setuptools import Extension, setup

setup(ext_modules=[
    Extension("cclogfs.codecs._rows", ["cclogfs/codecs/_rows.c"], optional=True),
    Extension("cclogfs.codecs._planes", ["cclogfs/codecs/_planes.c"], optional=True),
    Extension("cclogfs.ingest._jsonl_split", ["cclogfs/ingest/_jsonl_split.c"], optional=True),
    Extension("cclogfs.classifier._odomtext", ["cclogfs/classifier/_odomtext.c"], optional=True),
    # The same doubles as the Python stream: no fused multiply-adds (aarch64 would fuse).
    Extension("cclogfs.classifier._stream", ["cclogfs/classifier/_stream.c"], optional=True,
              extra_compile_args=["-ffp-contract=off"]),
])
