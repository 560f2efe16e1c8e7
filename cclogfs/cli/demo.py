"""`cclog demo`: the whole pipeline on simulated robot runs."""

from __future__ import annotations

import argparse
from pathlib import Path

EXAMPLES = """\
examples:
  cclog demo                       # about a minute on 2 cores; writes out/demo/
  cclog demo --test-minutes 10 --rate 30 --anomalies 10
"""


DESCRIPTION = (
    "Simulate nominal driving and train on it, smart-log a different "
    "run with labelled anomalies into a store, and report detection "
    "quality and storage, with plots."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="out/demo", help="output directory (default out/demo)")
    p.add_argument("--train-minutes", type=float, default=3.0, help="nominal driving to train on")
    p.add_argument("--test-minutes", type=float, default=5.0, help="length of the run to smart-log")
    p.add_argument("--rate", type=float, default=100.0, help="odometry rate in Hz (default 100)")
    p.add_argument("--anomalies", type=int, default=6, help="anomalies in the test run")
    p.add_argument("--seed", type=int, default=101, help="seed of the test run")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")


def run(args: argparse.Namespace) -> int:
    from ..demo import DemoConfig, run_demo
    from .outputs import refuse_store_dir

    refuse_store_dir(args.out)  # the demo's model, runs and stores would land among a store's segments
    run_demo(DemoConfig(out=Path(args.out), train_minutes=args.train_minutes, test_minutes=args.test_minutes,
                        rate_hz=args.rate, anomalies=args.anomalies, test_seed=args.seed,
                        plots=not args.no_plots))  # fmt: skip
    return 0
