"""`cclog eval`: score a labelled run as smart logging would, without storing anything."""

from __future__ import annotations

import argparse

from .common import human_bytes, load_labels, model_fits

EXAMPLES = """\
examples:
  cclog eval test.mcap --model odom.model --labels test.labels.json
  cclog eval test.mcap --model odom.model --labels test.labels.json --before 4s --after 4s
"""


DESCRIPTION = (
    "Replay a labelled run through smart logging and report the "
    "paper's per-message Table 1, per-event recall and precision, "
    "and the fraction of messages and bytes that would be kept."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..pipeline import WINDOW_AFTER, WINDOW_BEFORE

    p.add_argument("source", help="bag, MCAP or JSONL file")
    p.add_argument("--model", required=True, help="model directory")
    p.add_argument("--labels", required=True, help='{"events": [{"start_ns", "end_ns", "kind"}]}')
    p.add_argument("--topic", action="append", metavar="T", help="topics logged with the windows (default all)")
    p.add_argument("--before", default=WINDOW_BEFORE, help="N messages or Ds (default %(default)s)")
    p.add_argument("--after", default=WINDOW_AFTER, help="N messages or Ds (default %(default)s)")
    p.add_argument("--odom-topic", metavar="T", help="the source's odometry topic to score (default: the model's)")
    p.add_argument("--force-model", action="store_true",
                   help="use the model even on a robot whose rate or motion is far outside its training")


def _is_bag(path: str) -> bool:
    from ..ingest import FORMATS, RosbagSource, detect_format

    return path != "-" and FORMATS.get(detect_format(path)) is RosbagSource


def run(args: argparse.Namespace) -> int:
    # Imported here, not at the top: `cclog --help` imports every subcommand module.
    from ..classifier import OneClassModel, format_event_table, format_message_table
    from ..ingest import open_source
    from ..pipeline import evaluate_run

    model = OneClassModel.load(args.model)
    odom_topic = args.odom_topic or model.topic
    topics = None if args.topic is None else sorted({*args.topic, odom_topic})
    # Labels are in header stamps (docs/CLASSIFIER.md), so the replay uses that clock.
    with open_source(args.source, topics=topics, clock="header" if _is_bag(args.source) else "log") as source:
        messages = [(m.topic, m.stamp_ns, m.text) for m in source]
    model_fits(model, args.model, args.source, odom_topic, force=args.force_model,
               texts=[text for t, _, text in messages if t == odom_topic])  # fmt: skip
    labels = load_labels(args.labels, [s for t, s, _ in messages if t == odom_topic], args.source, odom_topic)
    result = evaluate_run(messages, model, labels, before=args.before, after=args.after,
                          odom_topic=odom_topic)  # fmt: skip
    print("per message (the paper's Table 1):")
    print(format_message_table(result["messages"]))
    print("\nper event:")
    print(format_event_table(result["events"]))
    print(f"\nkept {result['kept_messages']:,} of {result['total_messages']:,} messages, "
          f"{human_bytes(result['kept_bytes'])} of {human_bytes(result['total_bytes'])} JSON "
          f"({100 * result['kept_bytes'] / max(result['total_bytes'], 1):.1f} %)")
    return 0
