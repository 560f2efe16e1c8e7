"""cclogfs: a storage engine for robot sensor logs."""

__version__ = "0.1.0"
