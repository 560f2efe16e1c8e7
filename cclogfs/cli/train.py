"""`cclog train`: learn mode. Fit a one-class SVM on nominal odometry; validate on labelled runs."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from ..errors import InvalidInputError, ModelError
from .common import check_odometry, load_labels
from .outputs import add_force, check_output, refuse_store_dir

EXAMPLES = """\
examples:
  cclog train nominal1.mcap nominal2.mcap --topic /odom --out odom.model
  cclog train run.mcap --labels run.labels.json --out odom.model     # labelled events are left out
  cclog train nominal.mcap --out odom.model --validate test.mcap --validate-labels test.labels.json
  cclog train dataset/ --out odom.model     # a labelled feature-vector directory (collect --features-out)

Labels: {"events": [{"start_ns": ..., "end_ns": ..., "kind": "..."}]} in the messages' header
stamps. With --validate, the paper's Table 1 is printed for the disjoint validation run.
"""


DESCRIPTION = "Fit a one-class SVM (RBF kernel) on the odometry of nominal runs."


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sources", nargs="+", help="bags, MCAP or JSONL files, or a feature-vector dataset directory")
    p.add_argument("--out", required=True,
                   help="model directory to write (an existing model is replaced only with --force)")
    add_force(p)
    p.add_argument("--topic", default="/odom", help="odometry topic (nav_msgs/Odometry; default /odom)")
    p.add_argument("--labels", action="append", metavar="JSON",
                   help="labels of the sources, one per source in order; their events are left out of training")
    p.add_argument("--features", default="default", choices=["default", "paper"], help="feature set")
    p.add_argument("--false-alarm-rate", type=float, default=0.001,
                   help="threshold: this fraction of held-out nominal vectors may score anomalous")
    p.add_argument("--validate", metavar="SOURCE", help="a disjoint labelled run to validate on")
    p.add_argument("--validate-labels", metavar="JSON", help="labels of --validate")


def run(args: argparse.Namespace) -> int:
    # Imported here, not at the top: `cclog --help` imports every subcommand module.
    from ..classifier import OneClassModel, format_message_table, load_dataset, make_features, message_table, train

    if args.labels and len(args.labels) != len(args.sources):
        raise InvalidInputError(f"--labels was given {len(args.labels)} times for {len(args.sources)} sources")
    if bool(args.validate) != bool(args.validate_labels):
        raise InvalidInputError("--validate and --validate-labels go together")
    if not 0 <= args.false_alarm_rate <= 1:  # nan and -1 were numpy's traceback after reading every run
        raise InvalidInputError(f"--false-alarm-rate must be a fraction from 0 to 1, not {args.false_alarm_rate}")
    _check_out(args)
    _check_disjoint(args)
    started = time.perf_counter()
    if args.validate:  # checked before training, so that a bad run fails in seconds, not after
        (validate,), _ = _read_runs([args.validate], args.topic, make_features(args.features), "score")
        validate_labels = load_labels(args.validate_labels, validate.stamp_ns, args.validate, args.topic)
    if len(args.sources) == 1 and (Path(args.sources[0]) / "dataset.json").is_file():
        config, nominal, anomalous = load_dataset(args.sources[0])
        model = OneClassModel(feature_config=config, topic=args.topic,
                              false_alarm_rate=args.false_alarm_rate)  # fmt: skip
        model.fit(nominal, anomalous if len(anomalous) else None)
        what = f"{len(nominal)} nominal vectors from {args.sources[0]}"
    else:
        runs, reports = _read_runs(args.sources, args.topic, make_features(args.features))
        # A left-out message would only repeat the vector before it: train without them.
        runs = [odom.take(r.accepted) if r.left_out else odom for odom, r in zip(runs, reports)]
        labels = None if not args.labels else [
            load_labels(p, odom.stamp_ns, src, args.topic) for p, odom, src in zip(args.labels, runs, args.sources)]
        try:
            model = train(runs, labels=labels, features=args.features, topic=args.topic,
                          false_alarm_rate=args.false_alarm_rate)  # fmt: skip
        except ModelError as err:
            if not any(r.left_out for r in reports):
                raise
            # Say which messages were missing, not only how few vectors were left.
            said = "; ".join(r.describe(src, args.topic) for src, r in zip(args.sources, reports) if r.left_out)
            raise ModelError(f"{str(err).rstrip('.')}: {said}.") from err
        _refuse_standing(model, runs)
        total = sum(r.total for r in reports)
        what = (f"{sum(len(r) for r in runs):,}" + (f" of {total:,}" if any(r.left_out for r in reports) else "")
                + f" {args.topic} messages from {len(runs)} run(s)")  # fmt: skip
    model.save(args.out)
    print(f"trained model {model.model_id_} on {what} in {time.perf_counter() - started:.1f} s: "
          f"{len(model.dual_coef_)} support vectors, nu={model.nu_:g}, gamma={model.gamma_:g}; saved {args.out}")
    if args.validate:
        from ..classifier import Detector

        _, flags = Detector(model).score_batch(validate)
        print(f"\nvalidation on {args.validate} (per message, as the paper's Table 1):")
        print(format_message_table(message_table(validate.stamp_ns, flags, validate_labels)))
    return 0


def _refuse_standing(model, runs: list) -> None:
    """Refuse a model of a robot that never drives in its training odometry (the rule:
    `classifier.fit.standing_still`): `record --model` would refuse the robot once it drove.
    Here, not in `classifier.train`, which may fit such a model on purpose (a model that
    finds every motion anomalous, for tests)."""
    from ..classifier.fit import standing_still

    if (why := standing_still(model.training)) is not None:
        seconds = sum((odom.stamp_ns[-1] - odom.stamp_ns[0]) / 1e9 for odom in runs if len(odom.stamp_ns))
        raise ModelError(f"The training odometry ({model.training['messages']:,} messages over {seconds:.1f} s) "
                         f"shows a robot standing still: {why}; train on runs in which the robot drives.")  # fmt: skip


def _check_disjoint(args: argparse.Namespace) -> None:
    """Refuse one run given twice (same content, any name, as `record` judges a source):
    as two sources its messages would be trained on twice, as --validate the Table 1 would
    score the training data itself."""
    from ..runs import content_key, source_fingerprint

    def content(path: str):
        try:
            fp = source_fingerprint(path)
        except OSError:
            return None  # reading it fails later, with the error that names it
        return None if fp is None else content_key(fp)

    seen: dict[tuple, str] = {}
    for src in args.sources:
        if (key := content(src)) is not None and key in seen:
            raise InvalidInputError(f"{src} and {seen[key]} are one run (same content): it would be trained on twice; "
                                    "give each run once.")  # fmt: skip
        seen.setdefault(key, src)
    if args.validate and (key := content(args.validate)) is not None and key in seen:
        raise InvalidInputError(f"--validate {args.validate} is the training run {seen[key]} (same content): "
                                "validate on a disjoint run.")  # fmt: skip


def _check_out(args: argparse.Namespace) -> None:
    """Refuse, before training, an --out that is (or is inside) an input, an existing model
    without --force, and any other non-empty directory even with it: `model.save` adds its
    two files to whatever directory it is given (a bag directory, a store) without a word."""
    out = args.out
    inputs = [*args.sources, *(args.labels or []), *filter(None, [args.validate, args.validate_labels])]
    refuse_store_dir(out)
    empty_dir = os.path.isdir(out) and not os.listdir(out)
    check_output(out, inputs, force=args.force or empty_dir, directory=True)
    if os.path.isdir(out) and not empty_dir and not (Path(out) / "model.json").is_file():
        raise InvalidInputError(f"Output {out} holds files but no model.json, so it is not a model directory; "
                                "--force replaces only a model: choose another output.")  # fmt: skip


def _read_runs(sources: list[str], topic: str, feature_set, job: str = "train on") -> tuple[list, list]:
    """(OdomArrays, `Usable` report) of each source's `topic`: an error for a source without
    it or whose every message the features leave out, a warning naming what was left out."""
    from ..classifier import parse_odometry
    from ..pipeline import read_topic

    runs, reports = [], []
    for src in sources:
        texts = [text for _, text in read_topic(src, topic)]
        if not texts:
            raise InvalidInputError(f"{src} has no messages on topic {topic}")
        try:
            runs.append(parse_odometry(texts))
        except InvalidInputError as err:
            raise InvalidInputError(f"{src}, topic {topic}: {err}") from err
        reports.append(check_odometry(runs[-1], feature_set, src, topic, job))
    return runs, reports
