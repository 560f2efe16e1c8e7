"""kill -9 attack on the real CLI: python kill9.py NAME TRIALS -- CMD with {S} for the store.

Each trial: fresh store (or a copy of --base), start CMD, SIGKILL after U(0.05, 3) s, then
fsck, fsck --repair if needed, fsck again, cat vs reference, info vs cat, and a second run.
"""
import json, os, random, shutil, signal, subprocess, sys, time

CCLOG = os.environ.get("CCLOG", "cclog")
REF = "full_m.cat"  # every message of tuc_corridor, in order


def run(*a, **k):
    return subprocess.run([CCLOG, *a], capture_output=True, text=True, **k)


def counts_from_info(store):
    p = run("info", "--json", store)
    if p.returncode != 0:
        return None, p.stderr.strip()
    d = json.loads(p.stdout)
    return sum(s["messages"] for n, s in d["streams"].items() if not n.startswith("/cclog/")), d


def main():
    name, trials = sys.argv[1], int(sys.argv[2])
    i = sys.argv.index("--")
    opts = sys.argv[3:i]
    cmd = sys.argv[i + 1:]
    base = opts[opts.index("--base") + 1] if "--base" in opts else None
    mode = opts[opts.index("--mode") + 1] if "--mode" in opts else "prefix"
    hi = float(opts[opts.index("--hi") + 1]) if "--hi" in opts else 3.0
    ref = open(REF).read().splitlines()
    refpos = {l: k for k, l in enumerate(ref)}
    after = []
    if mode == "keep":
        store = f"k_{name}_full"
        shutil.rmtree(store, ignore_errors=True)
        shutil.copytree(base, store)
        assert run(*[a.replace("{S}", store) for a in cmd]).returncode in (0, 3)
        after = run("cat", store).stdout.splitlines()
        print(f"full compaction keeps {len(after)} lines")
    rng = random.Random(int(os.environ.get("SEED", "1")))
    bad = 0
    landed = 0
    for t in range(trials):
        store = f"k_{name}"
        shutil.rmtree(store, ignore_errors=True)
        if base:
            shutil.copytree(base, store)
        argv = [a.replace("{S}", store) for a in cmd]
        before = run("cat", store).stdout.splitlines() if base else []
        delay = rng.uniform(0.05, hi)
        p = subprocess.Popen([CCLOG, *argv], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if not base:  # the kill lands after the store exists (start-up is seconds on a loaded machine)
            t0 = time.time()
            while p.poll() is None and not os.path.exists(store + "/MANIFEST") and time.time() - t0 < 60:
                time.sleep(0.01)
        time.sleep(delay)
        alive = p.poll() is None
        if alive:
            p.send_signal(signal.SIGKILL)
            landed += 1
        p.wait()
        problems = []
        if not os.path.exists(store + "/MANIFEST"):
            print(f"[{t}] {delay:.2f}s killed={alive} no store yet")
            continue
        f1 = run("fsck", store)
        fr = None
        if f1.returncode != 0:
            fr = run("fsck", "--repair", store)
            f2 = run("fsck", store)
            if f2.returncode != 0:
                problems.append(f"fsck after repair rc={f2.returncode}: {f2.stdout[-300:]} {f2.stderr[-300:]}")
        c = run("cat", store)
        lines = c.stdout.splitlines()
        if c.returncode != 0 and not (not lines and "holds no messages" in c.stderr):
            problems.append(f"cat rc={c.returncode}: {c.stderr.strip()[:300]}")
        # order check against the reference
        if mode == "stamps":  # aged while recorded: values within bounds, every stamp kept
            rs = {json.loads(l)["stamp_ns"]: k for k, l in enumerate(ref)}
            pos = [rs.get(json.loads(l)["stamp_ns"], -1) for l in lines]
        else:
            pos = [] if mode == "keep" else [refpos.get(l, -1) for l in lines]
        if -1 in pos:
            problems.append(f"cat gives {pos.count(-1)} lines not in the reference")
        elif pos:
            if mode == "prefix" and pos != list(range(len(pos))):
                problems.append(f"not a prefix: first={pos[0]} len={len(pos)} last={pos[-1]}")
            if mode in ("slice", "stamps") and pos != list(range(pos[0], pos[0] + len(pos))):
                problems.append(f"not a slice: first={pos[0]} len={len(pos)} last={pos[-1]}")
            if mode == "sorted" and any(b <= a for a, b in zip(pos, pos[1:])):
                problems.append("reordered or duplicated")
        if mode == "keep":
            # compaction: every line is one from before or one the finished compaction gives;
            # from the first stamp the result holds on, no line the finished compaction keeps is missing
            allowed = set(before) | set(after)
            stamps = [json.loads(l)["stamp_ns"] for l in lines]
            if any(l not in allowed for l in lines):
                problems.append(f"{sum(l not in allowed for l in lines)} lines neither before nor after compaction")
            if any(b <= a for a, b in zip(stamps, stamps[1:])):
                problems.append("stamps reordered or duplicated")
            got = set(stamps)
            if stamps:
                miss = [l for l in after if json.loads(l)["stamp_ns"] >= stamps[0] and json.loads(l)["stamp_ns"] not in got]
                if miss:
                    problems.append(f"{len(miss)} messages the finished compaction keeps are missing")
        n, d = counts_from_info(store)
        if n is None:
            problems.append(f"info failed: {d}")
        elif n != len(lines):
            problems.append(f"info says {n} messages, cat gave {len(lines)}")
        second = None
        if "--again" in opts:
            s = run(*argv)
            second = s.returncode
            c2 = run("cat", store).stdout.splitlines()
            if s.returncode == 0 and mode == "prefix" and c2 != ref:
                problems.append(f"second run rc=0 but cat has {len(c2)} lines, not the full {len(ref)}")
            if s.returncode != 0 and len(s.stderr.strip().splitlines()) != 1:
                problems.append(f"second run refused unclearly: {s.stderr[-400:]}")
            if s.returncode != 0:
                second = (s.returncode, s.stderr.strip()[:160])
        status = "BAD" if problems else "ok"
        bad += bool(problems)
        print(f"[{t}] {delay:.2f}s killed={alive} fsck={f1.returncode} repair={fr and fr.returncode} lines={len(lines)} second={second} {status}")
        for pr in problems:
            print("    ", pr)
        if problems:
            keep = f"bad_{name}_{t}"
            shutil.rmtree(keep, ignore_errors=True)
            shutil.copytree(store, keep)
    print(f"{name}: {trials} trials, {landed} killed mid-run, {bad} bad")


main()
