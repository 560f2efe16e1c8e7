"""Detection quality on real odometry with injected anomalies, default vs paper features.

Two folds over ../shared/data/nav2_turtlebot.mcap /odom (97 s): train on one half, test on
the other; each anomaly kind is injected into its own copy of the test half, and the clean
test half counts false windows. Rates: native (~27 Hz), and resampled to 10 and 100 Hz with
stamp jitter. Run: python bench/classifier_eval.py [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from cclogfs.classifier.api import Detector, SmartLogger, train  # noqa: E402
from cclogfs.classifier.evaluate import event_table, message_table, window_spans  # noqa: E402
from cclogfs.classifier.features import NS, OdomArrays, parse_odometry  # noqa: E402
from cclogfs.errors import ModelError  # noqa: E402
from cclogfs.classifier.testing import inject, odom_texts, read_odometry, resample  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "nav2_turtlebot.mcap"
DURATION_S = {"accel": 0.4, "pose_jump": 0.0, "spin": 4.0, "stop": 3.0, "twist": 0.4,
              "oscillate": 6.0}  # fmt: skip


def runs_at(odom: OdomArrays, rate):
    if rate is None:
        return odom
    return resample(odom, rate, jitter_s=0.2 / rate, seed=rate)


def evaluate(odom: OdomArrays, features: str, window_args: dict, seed: int = 0, **params) -> dict:
    t = odom.stamp_ns
    mid = t[0] + (t[-1] - t[0]) // 2
    halves = [odom.take(t < mid), odom.take(t >= mid)]
    rng = np.random.default_rng(seed)
    totals = {"msg": [], "evt": [], "train_s": 0.0}
    for fold in (0, 1):
        train_run, test_run = halves[fold], halves[1 - fold]
        t0 = time.perf_counter()
        model = train([train_run], features=features, **params)
        totals["train_s"] += time.perf_counter() - t0
        tt = test_run.stamp_ns
        cases = [(test_run, {"events": []})]
        for kind, dur in DURATION_S.items():
            # While driving (> 0.2 m/s): stopping or lurching when parked is no anomaly.
            ok = (tt > tt[0] + 12 * NS) & (tt < tt[-1] - int((dur + 10) * NS))
            ok &= np.hypot(test_run.raw[:, 7], test_run.raw[:, 8]) > 0.2
            start = int(rng.choice(tt[ok]))
            run, event = inject(test_run, kind, start, dur)
            cases.append((run, {"events": [event]}))
        for run, labels in cases:
            detector = Detector(model)
            scores, flags = detector.score_batch(run)
            texts = odom_texts(run)
            logger = SmartLogger(Detector(model), summary_period_s=None, **window_args)
            windows = logger.replay([("/odom", int(s), x) for s, x in zip(run.stamp_ns, texts)])
            spans = window_spans(windows)
            totals["msg"].append(message_table(run.stamp_ns, flags, labels))
            et = event_table(run.stamp_ns, spans, labels)
            if et["recalled"] < et["events"]:
                e = labels["events"][0]
                hit = flags[(run.stamp_ns >= e["start_ns"]) & (run.stamp_ns <= e["end_ns"])].any()
                totals.setdefault("missed", []).append(e["kind"] + ("(partly)" if hit else ""))
            totals["evt"].append(et | {"clean": not labels["events"]})
    return totals


def summarize(res: dict) -> dict:
    m = {k: sum(r[k] for r in res["msg"]) for k in ("tp", "fp", "fn", "tn")}
    ev = res["evt"]
    events = sum(e["events"] for e in ev)
    recalled = sum(e["recalled"] for e in ev)
    windows = sum(e["windows"] for e in ev)
    false = sum(e["false_windows"] for e in ev)
    clean = [e for e in ev if e["clean"]]
    clean_min = sum(e["minutes"] for e in clean)
    return {
        "msg_prec": m["tp"] / max(1, m["tp"] + m["fp"]), "msg_rec": m["tp"] / max(1, m["tp"] + m["fn"]),
        "events": events, "recalled": recalled, "windows": windows, "false": false,
        "win_prec": (windows - false) / windows if windows else float("nan"),
        "clean_false_10min": sum(e["false_windows"] for e in clean) * 10 / clean_min,
        "clean_min": clean_min,
        "kept": np.mean([e["kept_fraction"] for e in clean]),
        "train_s": res["train_s"] / 2,
        "missed": ",".join(res.get("missed", [])),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--features", nargs="+", default=["default", "paper"])
    ap.add_argument("--rates", nargs="+", default=["native", "10", "100"])
    ap.add_argument("--window-seconds", type=float, default=None,
                    help="before/after in seconds instead of 100 messages")
    args = ap.parse_args()
    odom = parse_odometry(read_odometry(DATA))
    wargs = ({"before_s": args.window_seconds, "after_s": args.window_seconds}
             if args.window_seconds else {"before": 100, "after": 100})
    print(f"windows: {wargs}; 2 folds x (1 clean + {len(DURATION_S)} injected) test runs per row")
    head = (f"{'features':<8} {'rate':>6} {'msg P':>6} {'msg R':>6} {'events':>7} {'ev rec':>7} "
            f"{'windows':>7} {'false':>5} {'win P':>6} {'clean false/10min':>17} {'clean min':>9} "
            f"{'kept(clean)':>11} {'train s':>7}  missed events")
    print(head)
    for features in args.features:
        for rate in args.rates:
            run = runs_at(odom, None if rate == "native" else int(rate))
            try:
                s = summarize(evaluate(run, features, wargs))
            except ModelError as err:  # e.g. a 500-message window longer than the half run
                print(f"{features:<8} {rate:>6} n/a: {err}")
                continue
            print(f"{features:<8} {rate:>6} {s['msg_prec']:6.1%} {s['msg_rec']:6.1%} {s['events']:>7} "
                  f"{s['recalled'] / s['events']:7.1%} {s['windows']:>7} {s['false']:>5} "
                  f"{s['win_prec']:6.1%} {s['clean_false_10min']:17.2f} {s['clean_min']:9.2f} "
                  f"{s['kept']:11.1%} {s['train_s']:7.2f}  {s['missed']}", flush=True)


if __name__ == "__main__":
    main()
