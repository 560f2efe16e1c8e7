"""The optional compiled helper of the columnar encoder (issue 14); everything else is in
pyproject.toml. `optional=True`: without a C compiler the install still succeeds, and
cclogfs takes the pure-Python path, which gives the same bytes (cclogfs/codecs/shapes.py)."""

from setuptools import Extension, setup

setup(ext_modules=[Extension("cclogfs.codecs._rows", ["cclogfs/codecs/_rows.c"], optional=True)])
