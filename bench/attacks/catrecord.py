"""cat in a loop while record (with --budget or not) writes: every cat that exits 0 must print
a contiguous run of the full recording, in order (a prefix without a budget)."""
import os, subprocess, sys, shutil
C = os.environ.get("CCLOG", "cclog")
ref = open("full_m.cat").read().splitlines()
pos = {l: i for i, l in enumerate(ref)}
extra = sys.argv[1:]
bad = n = 0
for trial in range(3):
    shutil.rmtree("cr2", ignore_errors=True)
    p = subprocess.Popen([C, "record", "corr.jsonl", "--store", "cr2", "--sync-ms", "20", *extra],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    while p.poll() is None:
        if not os.path.exists("cr2/MANIFEST"):
            continue
        c = subprocess.run([C, "cat", "cr2"], capture_output=True, text=True)
        n += 1
        lines = c.stdout.splitlines()
        ps = [pos.get(l, -1) for l in lines]
        ok = c.returncode != 0 or (-1 not in ps and ps == list(range(ps[0], ps[0] + len(ps))) if ps else True)
        if c.returncode == 0 and not extra and ps and ps[0] != 0:
            ok = False
        if not ok or (c.returncode not in (0,) and "holds no messages" not in c.stderr):
            print("cat", c.returncode, len(lines), ps[:1], ps[-1:], c.stderr.strip()[:300])
            bad += not ok
print(f"{n} cats during record {extra}, {bad} bad")
