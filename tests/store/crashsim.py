"""The crash model the store's crash tests share; it lives in bench/_diskmodel.py so that
`python3 dev.py bench crash` (the soak) runs the same model as the tests."""

from bench._diskmodel import MODES, SECTOR, DiskModel, Inode  # noqa: F401
