"""Flip one byte of a store's file, run cat, info --json, export --mcap (forked CLI main),
and hold each to: exactly the original output with exit 0, or a non-zero exit naming the file.

    python flip.py STORE TRIALS [FILE_GLOB]   (SEED env)
"""
import fnmatch, hashlib, os, random, shutil, sys, tempfile

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
from cclogfs.cli import main as cli_main  # noqa: E402
import cclogfs.cli.cat, cclogfs.cli.info, cclogfs.cli.export  # noqa: F401,E402  (warm imports before fork)

TMP = tempfile.mkdtemp(prefix="flip_", dir=os.getcwd())


def forked(argv):
    out, err = os.path.join(TMP, "out"), os.path.join(TMP, "err")
    pid = os.fork()
    if pid == 0:
        fo = os.open(out, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
        fe = os.open(err, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
        os.dup2(fo, 1)
        os.dup2(fe, 2)
        try:
            rc = cli_main(argv)
        except BaseException:
            import traceback
            traceback.print_exc()
            rc = 99
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(rc)
    _, st = os.waitpid(pid, 0)
    rc = os.waitstatus_to_exitcode(st)
    return rc, open(out, "rb").read(), open(err, errors="replace").read()


def views(store, export=True):
    mc = os.path.join(TMP, "x.mcap")
    res = {}
    res["cat"] = forked(["cat", store])
    r = forked(["info", "--json", store])
    res["info"] = r
    if os.path.exists(mc):
        os.unlink(mc)
    if not export:
        return res
    rc, o, e = forked(["export", "--mcap", mc, "--force", store])
    digest = hashlib.sha256(open(mc, "rb").read()).hexdigest() if rc == 0 and os.path.exists(mc) else ""
    res["export"] = (rc, digest.encode(), e)
    return res


def main():
    src, trials = sys.argv[1], int(sys.argv[2])
    pat = sys.argv[3] if len(sys.argv) > 3 else "*"
    rng = random.Random(int(os.environ.get("SEED", "1")))
    base = views(src)
    for k, (rc, o, e) in base.items():
        assert rc == 0, (k, rc, e)
    files = sorted(f for f in os.listdir(src) if fnmatch.fnmatch(f, pat) and f not in ("RESERVE",))
    work = os.path.join(TMP, "store")
    tally = {}
    for t in range(trials):
        name = files[t % len(files)]
        shutil.rmtree(work, ignore_errors=True)
        shutil.copytree(src, work)
        path = os.path.join(work, name)
        data = bytearray(open(path, "rb").read())
        if not data:
            continue
        off = rng.randrange(len(data))
        data[off] ^= rng.randrange(1, 256)
        open(path, "wb").write(bytes(data))
        got = views(work, export=t % 4 == 0)
        for cmd, (rc, o, e) in got.items():
            if cmd == "info":
                o = o.replace(work.encode(), src.encode())
                e = e + o.decode(errors="replace")[-2000:] if rc else e
            brc, bo, be = base[cmd]
            if "Traceback" in e:
                verdict = "TRACEBACK"
            elif rc == 0 and o == bo:
                verdict = "same" if not e.strip() or e == be else "same+warn"
            elif rc == 0:
                verdict = "SILENT-DIFF" if not e.strip() or e == be else "diff+warn"
            elif name in e or name.split(".")[0].lstrip("0") in e:
                verdict = "refused-named"
            else:
                verdict = "REFUSED-UNNAMED"
            key = (name.split(".")[-1] if "." in name else name, cmd, verdict)
            tally[key] = tally.get(key, 0) + 1
            if verdict.isupper() or verdict in ("diff+warn",) or (verdict == "REFUSED-UNNAMED"):
                print(f"[{t}] {name}@{off} {cmd}: {verdict} rc={rc} err={e.strip()[-300:]!r}")
                keep = f"flipbad_{os.path.basename(src)}_{t}"
                if not os.path.exists(keep):
                    shutil.copytree(work, keep)
    for k in sorted(tally):
        print(*k, tally[k])


main()
