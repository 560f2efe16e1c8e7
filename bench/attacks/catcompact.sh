# cat in a loop while compact rewrites: each cat gives every message (exact or aged) or fails non-zero
C=${CCLOG:-cclog}
for i in $(seq $1); do
  rm -rf tc; cp -r full_j tc
  $C compact tc --older-than 0s --error 1e-3 --max-rate $2 > /dev/null 2>&1 & a=$!
  while kill -0 $a 2>/dev/null; do
    $C cat tc > cc.out 2> cc.err; rc=$?; n=$(wc -l < cc.out); 
    echo "$i cat rc=$rc lines=$n $(head -c 200 cc.err)"
  done
  wait $a; echo "$i compact rc=$? final=$($C cat tc | wc -l)"
done
