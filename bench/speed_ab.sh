#!/bin/bash
# Whole-process A/B of issue 14's commands: this checkout (A) against an older commit (B),
# in alternating pairs with bench/ab.py (medians; quote the CPU ratio on a shared machine).
#   bash bench/speed_ab.sh [REV]      (REV default 8f10a52: main before issue 14)
# Needs the inputs of `python3 dev.py bench speed` (out/speed-data-300000-1000000-5-v2).
set -e
ROOT=$(cd "$(dirname "$0")/.." && pwd)
REV=${1:-8f10a52}
D=$ROOT/out/speed-data-300000-1000000-5-v2
PY=$ROOT/.venv/bin/python
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
# B in a subdirectory: `python -m` puts the working directory first on sys.path.
mkdir "$TMP/old" "$TMP/s" && git -C "$ROOT" archive "$REV" cclogfs | tar -x -C "$TMP/old"
head -30000 "$D/odom.jsonl" > "$TMP/odom30k.jsonl"
# Bytecode compiled for both, as an install would (PYTHONDONTWRITEBYTECODE=1 otherwise
# makes every run compile every module).
$PY -m compileall -q "$ROOT/cclogfs" "$TMP/old/cclogfs" > /dev/null
read -r start end _ < "$D/one_s" || true  # the file has no final newline
A="env PYTHONPATH=$ROOT $PY -m cclogfs"
B="env PYTHONPATH=$TMP/old $PY -m cclogfs"
show() { grep -E "cpu s|wall s|peak MiB|A/B (cpu|wall)|exit"; }
cd "$TMP"
echo "=== cclog --help"; $PY $ROOT/bench/ab.py -n 9 --vs "$B --help" -- $A --help 2>&1 | show
echo "=== cat 1 s of the 1M-message store"
$PY $ROOT/bench/ab.py -n 7 --timeout 200 --vs "$B cat $D/big.store --start $start --end $end" -- \
  $A cat "$D/big.store" --start "$start" --end "$end" 2>&1 | show
echo "=== cat of the 300k-message store (full scan)"
$PY $ROOT/bench/ab.py -n 3 --timeout 400 --vs "$B cat $D/small.store" -- $A cat "$D/small.store" 2>&1 | show
for args in "odom30k.jsonl" "$D/sim.bag" "odom30k.jsonl --model $D/model --force-model"; do
  echo "=== record $args"
  $PY $ROOT/bench/ab.py -n 5 --timeout 600 \
    --vs "sh -c 'rm -rf s/b; PYTHONPATH=$TMP/old exec $PY -m cclogfs record $args --store s/b'" -- \
    sh -c "rm -rf s/a; PYTHONPATH=$ROOT exec $PY -m cclogfs record $args --store s/a" 2>&1 | show
done
