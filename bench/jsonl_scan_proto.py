"""What a compiled JSONL splitter would save `cclog record` (issue 14): a prototype timed.

    python3 dev.py bench jsonl_scan_proto [--lines 60000] [--rounds 5]

bench/_jsonl_scan_proto.c (built here with the system C compiler; cclogfs does not use
it) does in C what JsonlSource does per canonical line: match the layout, check the
msg against the JSON grammar and its strings' UTF-8, and make (topic, stamp_ns, text).
It is checked to give JsonlSource's messages for every line of the input, then both are
timed (smallest CPU time of interleaved rounds) beside the orjson floor.
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sysconfig
import tempfile
from pathlib import Path

from ._util import OUT
from .record_floor import smallest_cpu, speed_lines


def build(tmp: Path):
    src = Path(__file__).with_name("_jsonl_scan_proto.c")
    so = tmp / ("_jsonl_scan_proto" + sysconfig.get_config_var("EXT_SUFFIX"))
    subprocess.run(["gcc", "-O2", "-shared", "-fPIC", f"-I{sysconfig.get_paths()['include']}", str(src), "-o", str(so)],
                   check=True)  # fmt: skip
    spec = importlib.util.spec_from_file_location("_jsonl_scan_proto", so)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main() -> int:
    import orjson

    from cclogfs.ingest.jsonl import JsonlSource

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lines", type=int, default=60_000)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    _, lines = speed_lines(args.lines)
    with tempfile.TemporaryDirectory(dir=OUT) as tmp:
        proto = build(Path(tmp))
        part = Path(tmp) / "part.jsonl"
        part.write_bytes(b"".join(lines))
        with JsonlSource(part) as source:
            want = [(m.topic, m.stamp_ns, m.text) for m in source]
        assert proto.scan(lines) == want, "the prototype does not give JsonlSource's messages"

        def floor():
            for line in lines:
                orjson.loads(line)

        def source():
            with JsonlSource(part) as s:
                for _ in s:
                    pass

        def scanned():  # read the lines as JsonlSource does, then split them in C
            with open(part, "rb", buffering=1 << 16) as f:
                while chunk := f.readlines(1 << 16):
                    proto.scan(chunk)

        stages = {"orjson.loads per line (the floor)": floor, "JsonlSource": source, "prototype: read + scan in C": scanned}
        best = smallest_cpu(stages, args.rounds)
    for name, secs in best.items():
        print(f"{name:<40} {1e6 * secs / args.lines:6.2f} us/msg")
    return 0
