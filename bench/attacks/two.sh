# two writers started at once on a missing store: one must be refused, the store clean
C=${CCLOG:-cclog}
L=${DATA:-../shared/data}/long/slamfail_cps_lab.mcap
for i in $(seq $1); do
  rm -rf tw; 
  $C record corr.jsonl --store tw > tw1.out 2>&1 & a=$!
  $C record $L --store tw > tw2.out 2>&1 & b=$!
  wait $a; ra=$?; wait $b; rb=$?
  f=$($C fsck tw 2>&1 | tail -1); n=$($C info --json tw | python3 -c 'import json,sys; d=json.load(sys.stdin); print(len(d["runs"]), {k:v["messages"] for k,v in d["streams"].items()})')
  echo "$i ra=$ra rb=$rb | $f | $n | $(grep error tw1.out tw2.out | cut -c1-150)"
done
