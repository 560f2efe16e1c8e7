"""The demo: the whole of cclogfs on simulated robot runs, in a couple of minutes.

Simulate nominal driving and train a model on it (learn mode); simulate a different run
with labelled anomalies, write it as a ROS 2 bag, and smart-log that bag into a store;
log it again keeping everything, for comparison; then report detection quality (the
paper's Table 1 and per-event figures, from what the store holds) and storage, and draw
the trajectory and the anomaly score with the stored windows.
"""

from __future__ import annotations

import lzma
import shutil
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..classifier import Detector, event_table, format_message_table, message_table, parse_odometry, train
from ..ingest import open_source
from ..pipeline import WINDOW_AFTER, WINDOW_BEFORE, KeepAll, record, smart_policy
from ..sim import simulate
from ..store import open_store
from ..textfmt import human_bytes, table
from ..upkeep import Policy, compact, parse_rule
from ..windowcount import WindowJoiner, link_of

TOPICS = ["/odom", "/imu"]
# The error bound the demo ages a copy of its store to: 1 mm, 1 mrad, 1 mm/s.
AGED_ERROR = "1e-3"


@dataclass
class DemoConfig:
    out: Path = Path("out/demo")
    train_minutes: float = 3.0
    test_minutes: float = 5.0
    rate_hz: float = 100.0
    anomalies: int = 6
    severity: tuple[float, float] = (0.5, 1.5)
    train_seeds: tuple[int, ...] = (1, 2)
    test_seed: int = 101
    # one robot for training and test (a model is per robot), odometry yaw from its IMU
    robot_seed: int = 1
    heading: str = "imu"
    before: str = WINDOW_BEFORE
    after: str = WINDOW_AFTER
    plots: bool = True


@dataclass
class DemoResult:
    """Everything the demo printed, for tests to check against the store."""

    paths: dict[str, Path] = field(default_factory=dict)
    messages: dict[str, Any] = field(default_factory=dict)
    events: dict[str, Any] = field(default_factory=dict)
    storage: list[tuple[str, int]] = field(default_factory=list)
    json_bytes: int = 0
    stored_windows: list[tuple[int, int]] = field(default_factory=list)


class Steps:
    """Numbered progress lines on stderr with the time each step took."""

    def __init__(self, total: int):
        self.total, self.n, self.t = total, 0, time.perf_counter()

    def __call__(self, text: str) -> None:
        self.done()
        self.n += 1
        self.t = time.perf_counter()
        print(f"[{self.n}/{self.total}] {text} ...", end="", file=sys.stderr, flush=True)

    def done(self) -> None:
        if self.n:
            print(f" {time.perf_counter() - self.t:.1f} s", file=sys.stderr, flush=True)


def _clean(out: Path) -> None:
    """Remove what an earlier demo run wrote (only that), so a second run works."""
    for name in ("train", "test", "model", "store", "store-all", "store-aged", "trajectory.png", "scores.png"):
        p = out / name
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()


def run_demo(cfg: DemoConfig) -> DemoResult:
    out = cfg.out
    out.mkdir(parents=True, exist_ok=True)
    _clean(out)
    res = DemoResult(paths={"store": out / "store", "store_all": out / "store-all", "store_aged": out / "store-aged",
                            "model": out / "model",
                            "bag": out / "test" / "run", "labels": out / "test" / "labels.json"})  # fmt: skip
    step = Steps(7 if cfg.plots else 6)
    model = _train(cfg, res, step)

    step(f"simulating a different {cfg.test_minutes:g} min run with {cfg.anomalies} anomalies, as a ROS 2 bag")
    run = simulate(seed=cfg.test_seed, duration_s=cfg.test_minutes * 60, rate_hz=cfg.rate_hz,
                   anomalies=cfg.anomalies, severity=cfg.severity, robot_seed=cfg.robot_seed,
                   heading=cfg.heading)  # fmt: skip
    run.write(out / "test", imu=True)
    labels = run.labels_dict()

    step("smart logging the bag into a store, and (for comparison) keeping everything in another")
    with open_source(res.paths["bag"]) as source:
        all_messages = list(source)
    json_all = "\n".join(m.text for m in all_messages).encode()
    res.json_bytes = len(json_all)
    lzma_size: list[int] = []
    lzma_thread = threading.Thread(target=lambda: lzma_size.append(len(lzma.compress(json_all, preset=6))))
    lzma_thread.start()  # the paper's best compressor, on the other core (lzma releases the GIL)
    _log(cfg, res, model, all_messages)

    step("scoring: the paper's Table 1 and per-event figures, from what the store holds")
    odom = parse_odometry([m.text for m in all_messages if m.topic == "/odom"])
    scores, flags = Detector(model).score_batch(odom)
    res.stored_windows = _stored_windows(res.paths["store"])
    res.messages = message_table(odom.stamp_ns, flags, labels)
    res.events = event_table(odom.stamp_ns, res.stored_windows, labels)
    step(f"waiting for LZMA-6 (the paper's best) to finish compressing all {res.json_bytes / 2**20:.0f} MiB of JSON")
    lzma_thread.join()
    res.storage = [
        ("raw JSON (every message)", res.json_bytes),
        ("LZMA-6 of all the JSON (the paper's best)", lzma_size[0]),
        ("cclogfs, every message kept", _disk(res.paths["store_all"])),
        ("cclogfs, smart logging", _disk(res.paths["store"])),
        (f"cclogfs, smart logging, aged to {AGED_ERROR} (cclog compact)", _disk(res.paths["store_aged"])),
    ]
    if cfg.plots:
        step("drawing the trajectory and the anomaly score")
        from ..plot.figures import plot_scores, plot_trajectory  # matplotlib only when plotting

        res.paths["trajectory"] = plot_trajectory(out / "trajectory.png", run, res.stored_windows)
        res.paths["scores"] = plot_scores(out / "scores.png", odom.stamp_ns, scores, res.stored_windows,
                                          labels["events"])  # fmt: skip
    step.done()
    _report(cfg, res, run, len(all_messages))
    return res


def _train(cfg: DemoConfig, res: DemoResult, step: Steps):
    """Simulate nominal driving, train the model on it and save it; the model."""
    step(f"simulating {cfg.train_minutes:g} min of nominal driving at {cfg.rate_hz:g} Hz for training")
    per_run = cfg.train_minutes * 60 / len(cfg.train_seeds)
    nominal = [simulate(seed=s, duration_s=per_run, rate_hz=cfg.rate_hz, robot_seed=cfg.robot_seed,
                        heading=cfg.heading) for s in cfg.train_seeds]  # fmt: skip

    step(f"training the one-class SVM on {sum(len(r) for r in nominal):,} odometry messages")
    model = train([[t for _, t in r.messages] for r in nominal], topic="/odom")
    model.save(res.paths["model"])
    return model


def _log(cfg: DemoConfig, res: DemoResult, model, messages: list) -> None:
    """The three stores: smart logging, every message, and an aged copy of the first."""
    with open_store(res.paths["store"], create=True) as store:
        record(messages, store, smart_policy(model, topics=TOPICS, before=cfg.before, after=cfg.after),
               check_json=False)  # fmt: skip
    with open_store(res.paths["store_all"], create=True) as store:
        record(messages, store, KeepAll(chunk=200), check_json=False)
    # What the windows cost once they are old: a copy aged as `cclog compact --error 1e-3`.
    shutil.copytree(res.paths["store"], res.paths["store_aged"], ignore=shutil.ignore_patterns("LOCK"))
    with open_store(res.paths["store_aged"]) as store:
        compact(store, policy=Policy([parse_rule(AGED_ERROR)]))


def _stored_windows(path: Path) -> list[tuple[int, int]]:
    """The logging windows the store holds (their parts joined as `cclog info` counts them,
    `windowcount`), as their /odom spans, in time order."""
    joiner = WindowJoiner()
    with open_store(path, readonly=True) as store:
        spans: dict[Any, list[int]] = {}
        for w in sorted(store.query(), key=lambda w: w.seq):
            key = joiner.join(w.name, link_of(w.meta), seq=w.seq, continues=w.continues)[0]
            if w.name == "/odom":
                s = spans.setdefault(key, [w.start_ns, w.end_ns])
                s[0], s[1] = min(s[0], w.start_ns), max(s[1], w.end_ns)
    return sorted((a, b) for a, b in spans.values())


def _disk(path: Path) -> int:
    return sum(p.stat().st_size for p in path.iterdir() if p.name != "LOCK")


def _report(cfg: DemoConfig, res: DemoResult, run: Any, n_messages: int) -> None:
    m, e = res.messages, res.events
    print(f"\ncclogfs demo: a {cfg.test_minutes:g}-minute simulated run at {cfg.rate_hz:g} Hz "
          f"({n_messages:,} messages on {', '.join(TOPICS)}), {len(run.events)} labelled anomalies "
          f"the model never saw, model trained on {cfg.train_minutes:g} min of nominal driving.\n")  # fmt: skip
    print("Per message, as the paper's Table 1 (a message is anomalous inside a labelled event):")
    print(format_message_table(m))
    print("\nPer event (an event is recalled when the stored windows cover all of it):")
    print(table([[f"{e['recalled']} of {e['events']}", f"{100 * e['event_recall']:.0f} %", e["windows"],
                  e["false_windows"], f"{100 * e['window_precision']:.0f} %", f"{100 * e['kept_fraction']:.1f} %"]],
                ["events recalled", "recall", "windows stored", "false windows", "precision",
                 "odometry kept"]))  # fmt: skip
    kinds = ", ".join(f"{ev.kind}" for ev in run.events)
    print(f"(anomalies: {kinds})")
    print("\nStorage:")
    raw = res.json_bytes
    print(table([[name, human_bytes(size), f"{100 * size / raw:.2f} %", f"{raw / size:.1f}x"]
                 for name, size in res.storage], ["", "size", "% of JSON", "reduction"]))  # fmt: skip
    store = res.paths["store"]
    print(f"\nThe store is in {store}. Look inside it:")
    print(f"  cclog info {store}")
    print(f"  cclog cat {store} --topic /odom | head -3")
    print(f"  cclog fsck {store} --deep")
    print(f"  cclog export {store} --mcap {cfg.out / 'windows.mcap'}    # open it in Foxglove")
    print(f"  cclog compact {store} --older-than 30d --error {AGED_ERROR}    # once it is old")
    if "trajectory" in res.paths:
        print(f"Plots: {res.paths['trajectory']} and {res.paths['scores']}")
