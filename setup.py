"""The optional compiled helpers (issue 14): the columnar encoder's row finder and the
classifier's odometry reader; everything else is in pyproject.toml. `optional=True`:
without a C compiler the install still succeeds, and cclogfs takes the pure-Python paths,
which give the same bytes (cclogfs/codecs/shapes.py) and values (classifier/features.py)."""

from setuptools import Extension, setup

setup(ext_modules=[
    Extension("cclogfs.codecs._rows", ["cclogfs/codecs/_rows.c"], optional=True),
    Extension("cclogfs.classifier._odomtext", ["cclogfs/classifier/_odomtext.c"], optional=True),
])
