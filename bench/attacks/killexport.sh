# kill -9 export at a random instant: no partial output under the final name, store clean, a rerun works
C=${CCLOG:-cclog}
for i in $(seq $1); do
  rm -rf ex; mkdir ex
  d=$(python3 -c "import random; print(round(random.uniform(0.3, 3.0), 3))")
  $C export full_j --mcap ex/out.mcap > /dev/null 2>&1 & a=$!; sleep $d; kill -9 $a 2>/dev/null && k=killed || k=done; wait $a 2>/dev/null
  left=$(ls -A ex | tr '\n' ' ')
  $C fsck full_j > /dev/null 2>&1; f=$?
  $C export full_j --mcap ex/out.mcap > ex.out 2>&1; r=$?
  echo "$i $d $k left=[$left] fsck=$f rerun=$r after=[$(ls -A ex | tr '\n' ' ')]"
done
