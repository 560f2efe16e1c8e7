"""The demo: the whole of cclogfs on simulated robot runs (`cclog demo`, `python3 dev.py
demo`). `run` drives it and prints the report; `plots` draws its PNGs (matplotlib is
imported only then)."""

from .run import DemoConfig, DemoResult, run_demo

__all__ = ["DemoConfig", "DemoResult", "run_demo"]
