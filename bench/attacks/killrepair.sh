# kill -9 fsck --repair (rebuilding a damaged MANIFEST and a missing index) at a random instant, then repair again
C=${CCLOG:-cclog}
for i in $(seq $1); do
  rm -rf kr; cp -r rb kr
  d=$(python3 -c "import random; print(round(random.uniform(0.1, 1.5), 3))")
  $C fsck --repair kr > /dev/null 2>&1 & a=$!; sleep $d; kill -9 $a 2>/dev/null && k=killed || k=done; wait $a 2>/dev/null
  $C fsck --repair kr > kr.out 2>&1; r=$?
  $C fsck kr > kr2.out 2>&1; f=$?
  $C cat kr 2>kr.err | cmp -s - hr.orig && s=same || s=DIFF
  q=$(ls kr/quarantine | wc -l)
  echo "$i $d $k repair=$r fsck=$f cat=$s quarantine=$q $(grep -v 'damage left\|quarantine' kr2.out | grep -i 'error\|warn' | head -2)"
done
