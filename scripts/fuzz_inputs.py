#!/usr/bin/env python3
"""Mutation fuzz of Duplex's file inputs: every damaged input must give exit 0 or a clean error
(exit 1 or 2 with a message on stderr), never a signal, a sanitizer report or a hang.

  json mode:   scripts/fuzz_inputs.py json --seeds DIR --count N -- build/bin/duplex trace --scene {} --rays R.bin --hits /tmp/h.bin
               mutates the scene files DIR/*.json (values replaced by special numbers, strings, nulls
               or containers; keys deleted; arrays cut or grown) and runs the command with {} = the mutant.
  binary mode: scripts/fuzz_inputs.py binary --file F --count N -- build/bin/duplex trace --scene S.json ...
               overwrites bytes, 4-byte words and 8-byte lengths of F in place (restored at the end) and
               runs the command, whose scene refers to F.

Use a sanitizer build (-DDUPLEX_SANITIZE=ON; ASAN_OPTIONS=detect_leaks=0, since OpenVDB leaks
nodes when it throws) to catch memory errors that do not crash. Damaged inputs that fail are kept
beside the output as crash_<n>. Exit status: 0 when no input failed, 1 otherwise."""
import argparse, copy, json, os, random, shutil, subprocess, sys
from collections import Counter

SPECIAL = [0, -0.0, -1, 1e-45, 2**32, 2**64, -2**31, 0.5, 3, 1e308, -1e308, 1e20, "x", "", None, [], {}, True, [1, 2]]


def paths(x, p=()):
    yield p
    if isinstance(x, dict):
        for k, v in x.items():
            yield from paths(v, p + (k,))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from paths(v, p + (i,))


def mutate_json(doc, rng):
    d = copy.deepcopy(doc)
    for _ in range(rng.randint(1, 3)):
        ps = [p for p in paths(d) if p]
        if not ps:
            break
        if rng.random() < 0.9:  # mostly structure, not the long vertex arrays
            ps = [p for p in ps if not any(k in ("positions", "indices") for k in p)] or ps
        p = rng.choice(ps)
        parent = d
        for k in p[:-1]:
            parent = parent[k]
        k = p[-1]
        r = rng.random()
        if r < 0.5:
            parent[k] = rng.choice(SPECIAL)
        elif r < 0.65:
            del parent[k]
        elif r < 0.8 and isinstance(parent[k], list) and parent[k]:
            parent[k] = parent[k][:rng.randrange(len(parent[k]))]
        elif r < 0.9 and isinstance(parent, list):
            parent.append(copy.deepcopy(parent[k]))
        else:
            v = parent[k]
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                parent[k] = v * rng.choice([-1, 1e6, 1e-6, 0])
            elif isinstance(v, str):
                parent[k] = v + rng.choice(["/", ".x", "\u00e9", "../../x", ""])
            else:
                parent[k] = rng.choice(SPECIAL)
    return d


def mutate_bytes(data, rng):
    b = bytearray(data)
    r = rng.random()
    if r < 0.2:
        return bytes(b[:rng.randrange(len(b))])
    if r < 0.6:
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return bytes(b)
    for _ in range(rng.randint(1, 3)):
        o = rng.randrange(max(1, len(b) - 8))
        if rng.random() < 0.5:
            word = rng.choice([0, 0xFFFFFFFF, 0x7FFFFFFF, 0x7FC00000, 0x7F800000, rng.randrange(2**32), rng.randrange(64)])
            b[o:o + 4] = word.to_bytes(4, "little")
        else:
            length = rng.choice([-rng.randrange(100000), rng.randrange(100000), 1 << 40, -1])
            b[o:o + 8] = length.to_bytes(8, "little", signed=True)
    return bytes(b)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mode", choices=["json", "binary"])
    ap.add_argument("--seeds", help="json: folder of seed scene files (*.json)")
    ap.add_argument("--file", help="binary: the file to damage in place")
    ap.add_argument("--count", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=60)
    argv = sys.argv[1:]
    if "--" not in argv or argv.index("--") == len(argv) - 1:
        ap.error("give the command to run after --")
    a = ap.parse_args(argv[:argv.index("--")])
    cmd = argv[argv.index("--") + 1:]
    if (a.mode == "json") != (a.seeds is not None) or (a.mode == "binary") != (a.file is not None):
        ap.error("json mode needs --seeds, binary mode --file")
    rng = random.Random(a.seed)
    codes, messages, failed = Counter(), Counter(), 0
    if a.mode == "json":
        seeds = [(f, json.load(open(os.path.join(a.seeds, f)))) for f in sorted(os.listdir(a.seeds))
                 if f.endswith(".json") and not f.startswith("mutant_")]
        if not seeds:
            ap.error("no seed *.json in " + a.seeds)
    else:
        original = open(a.file, "rb").read()
    try:
        for i in range(a.count):
            if a.mode == "json":
                name, doc = rng.choice(seeds)
                target = os.path.join(a.seeds, "mutant_" + name)
                with open(target, "w") as fh:
                    json.dump(mutate_json(doc, rng), fh)
                argv = [x.replace("{}", target) for x in cmd]
            else:
                target = a.file
                with open(target, "wb") as fh:
                    fh.write(mutate_bytes(original, rng))
                argv = cmd
            try:
                p = subprocess.run(argv, capture_output=True, text=True, errors="replace", timeout=a.timeout)
                rc, err = p.returncode, p.stderr
            except subprocess.TimeoutExpired:
                rc, err = "timeout", ""
            codes[rc] += 1
            if rc not in (0, "timeout") and err.strip():
                messages[err.strip().splitlines()[-1][:120]] += 1
            bad = rc == "timeout" or rc < 0 or rc > 2 or "Sanitizer" in err or "runtime error" in err or (rc != 0 and not err.strip())
            if bad:
                failed += 1
                keep = "crash_%d_%s" % (i, os.path.basename(target))
                shutil.copy(target, keep)
                print("FAILED (exit %s), kept as %s:\n%s" % (rc, keep, err[-1500:]), flush=True)
    finally:
        if a.mode == "binary":
            with open(a.file, "wb") as fh:
                fh.write(original)
    print("%d inputs, %d failed; exit codes %s" % (a.count, failed, dict(codes)))
    for m, c in messages.most_common(10):
        print("  %4d  %s" % (c, m))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
