"""Write encoded.bin of the columnar golden cases of one format version (output is committed).

    python tests/golden/make_columnar.py 2          # cases tests/golden/columnar/v2-*

Each case folder holds inputs.jsonl (stamp_ns, base64 text) and config.json. Only cases
without an encoded.bin are written: a payload, once committed, pins its format version.
To add a version, copy the input folders to v<N>-<name> with "version": N in config.json
and run this once. Never re-run it with --overwrite to make a failing golden test pass.
Inputs of v4-aged-odom are those of v3-odom with every float rounded to 3 places
(bench/codec_columnar.py's age_text); v4-decimal-kinds was written by hand to hold
DECIMAL columns of several digit counts beside columns that must fall back;
v4-keyed-tail holds scans whose last key is `"intensities": []` and texts with no value
(docs/CODEC_COLUMNAR.md, "Which texts have a group"), none of them raw.
"""

import argparse
import base64
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent.parent))

from cclogfs.codecs import codec_from_config  # noqa: E402

CASES = HERE / "columnar"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("version", type=int)
    parser.add_argument("--overwrite", action="store_true", help="rewrite existing payloads")
    args = parser.parse_args()
    cases = sorted(CASES.glob(f"v{args.version}-*"))
    if not cases:
        sys.exit(f"no case folders {CASES}/v{args.version}-*")
    for case in cases:
        out = case / "encoded.bin"
        if out.exists() and not args.overwrite:
            print(f"{out} exists, kept")
            continue
        config = json.loads((case / "config.json").read_text())
        if config.get("version") != args.version:
            sys.exit(f"{case}/config.json names version {config.get('version')}, not {args.version}")
        rows = [json.loads(line) for line in (case / "inputs.jsonl").read_text().splitlines()]
        texts = [base64.b64decode(r["text_b64"]).decode("utf-8", "surrogateescape") for r in rows]
        out.write_bytes(codec_from_config(config).encode([r["stamp_ns"] for r in rows], texts))
        print(f"{out}: {len(rows)} messages, {out.stat().st_size} bytes")


if __name__ == "__main__":
    main()
