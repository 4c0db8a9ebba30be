#!/usr/bin/python3
"""check_layers.py -- the layers of luxrad, checked on the built objects.

Usage: check_layers.py BUILD_DIR [--graph] [--partial]
       check_layers.py --self-test


Reads the symbols of every object file of the libraries below (nm) and
fails when
  - a library calls or reads a name that only a library above it defines
    (an upward call: the layers are listed lowest first), or
  - object files call each other in a loop (a cycle), inside a library or
    across libraries.
With --graph it also prints the file-to-file edges it found.  With
--partial, layers not built in BUILD_DIR are skipped (to measure an
older checkout's build, whose libraries had other names); the sources
are found through the build's CMakeCache.txt.  The self
test compiles a few objects with an upward call and a loop in a scratch
directory and checks that both are found (and nothing in a clean set).

Names defined by more than one object (none expected) are ignored; names
defined by no object of the project (libc, jansson, Embree...) are not
edges.  The command-line tools and tests are not layers: they sit on top.
"""
import collections
import glob
import os
import subprocess
import sys

# Lowest first: each may use only the ones before it.
LAYERS = [
    ("luxrad_options", "libluxrad_options.a"),
    ("luxrad_engine", "libluxrad_engine.a"),
    ("luxrad_photometry", "libluxrad_photometry.a"),
    ("luxrad_pack", "libluxrad_pack.a"),
    ("luxrad_sceneio", "libluxrad_sceneio.a"),
    ("luxrad_json", "libluxrad_json.a"),
    ("luxrad_protocol", "protocol/libluxrad_protocol.a"),
    ("luxrad_image", "client/libluxrad_image.a"),
    ("luxrad_modbus", "daemon/server/libluxrad_modbus.a"),
    ("luxrad_srvbase", "daemon/server/libluxrad_srvbase.a"),
    ("luxrad_store", "daemon/server/libluxrad_store.a"),
    ("luxrad_loop", "daemon/server/libluxrad_loop.a"),
    ("luxrad_core", "daemon/server/libluxrad_core.a"),
    ("luxradd (cmd/, main.c)", "daemon/server/CMakeFiles/luxradd.dir"),
]


def nm_lines(path):
    out = subprocess.run(["nm", "-A", "-g", path], capture_output=True,
                         text=True, check=True).stdout
    return out.splitlines()


def source_dir(build):
    """The source tree BUILD_DIR was configured from (CMakeCache.txt),
    else the one this script is in."""
    try:
        with open(os.path.join(build, "CMakeCache.txt")) as f:
            for line in f:
                if line.startswith("CMAKE_HOME_DIRECTORY:"):
                    return line.split("=", 1)[1].strip()
    except OSError:
        pass
    return os.path.dirname(os.path.dirname(os.path.dirname(
        os.path.abspath(__file__))))


def objects_of_target(build, objdir):
    """The target's object files whose source still exists (a renamed
    source's old object may still lie in the build tree)."""
    repo = source_dir(build)
    srcdir = os.path.join(repo, os.path.relpath(
        os.path.dirname(os.path.dirname(objdir)), build))
    found = glob.glob(os.path.join(objdir, "**", "*.o"), recursive=True)
    return sorted(o for o in found if os.path.exists(
        os.path.join(srcdir, os.path.relpath(o, objdir)[:-2])))


def objects_of(build, rel):
    """{object name: (defined set, undefined set)} of one layer."""
    path = os.path.join(build, rel)
    objs = collections.defaultdict(lambda: (set(), set()))
    paths = ([path] if path.endswith(".a") else
             objects_of_target(build, path))
    for p in paths:
        for line in nm_lines(p):
            # archive:member.o:  U name   |   file.o:0000 T name
            head, _, rest = line.rpartition(":")
            parts = rest.split()
            if len(parts) < 2:
                continue
            kind, name = parts[-2], parts[-1]
            member = head.rpartition(":")[2] if p.endswith(".a") else \
                os.path.relpath(head, path)
            if kind == "U":
                objs[member][1].add(name)
            elif kind in "TDBRVWCG":
                objs[member][0].add(name)
    return objs


def check(build, layers, graph=False, quiet=False, partial=False):
    """The number of problems found (upward uses and cycles)."""
    say = (lambda *a: None) if quiet else print
    layer_of, owner, undefined = {}, collections.defaultdict(set), {}
    per_layer = collections.Counter()
    for i, (name, rel) in enumerate(layers):
        if not os.path.exists(os.path.join(build, rel)):
            if partial:
                say(f"check_layers: no {rel} in {build}: skipped")
                continue
            raise SystemExit(f"check_layers: {rel} not built in {build}")
        objs = objects_of(build, rel)
        per_layer[name] = len(objs)
        for obj, (defs, undefs) in objs.items():
            node = f"{name}:{obj}"
            layer_of[node] = i
            undefined[node] = undefs
            for d in defs:
                owner[d].add(node)
    edges = collections.defaultdict(set)  # node -> {(node, name)}
    for node, undefs in undefined.items():
        for u in undefs:
            if len(owner.get(u, ())) == 1:
                target = next(iter(owner[u]))
                if target != node:
                    edges[node].add((target, u))
    bad = 0
    for node in sorted(edges):
        for target, u in sorted(edges[node]):
            if graph:
                say(f"{node} -> {target} ({u})")
            if layer_of[target] > layer_of[node]:
                say(f"upward: {node} uses {u} of {target}")
                bad += 1
    # Cycles: strongly connected components of more than one object.
    index, low, stack, on, sccs, n = {}, {}, [], set(), [], [0]

    def strong(v):
        index[v] = low[v] = n[0]
        n[0] += 1
        stack.append(v)
        on.add(v)
        for w, _ in edges.get(v, ()):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                sccs.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in sorted(layer_of):
        if v not in index:
            strong(v)
    for comp in sccs:
        names = set(comp)
        ties = [f"{a} -> {b} ({u})" for a in comp
                for b, u in sorted(edges.get(a, ())) if b in names]
        say(f"cycle of {len(comp)}: " + "; ".join(ties))
        bad += 1
    nedges = sum(len({t for t, _ in e}) for e in edges.values())
    say("objects per layer: " + ", ".join(
        f"{n} {per_layer[n]}" for n, _ in layers if n in per_layer))
    say(f"check_layers: {len(layer_of)} objects in {len(per_layer)} layers, "
        f"{nedges} file-to-file edges, {bad} problem(s)")
    return bad


SELF_TEST = {
    # layer "low": a.c calls up() of the layer above; c.c and d.c loop.
    "low/a.c": "int up(void); int a(void) { return up(); }",
    "low/c.c": "int d(int); int c(int n) { return n ? d(n - 1) : 0; }",
    "low/d.c": "int c(int); int d(int n) { return n ? c(n - 1) : 1; }",
    "high/b.c": "int up(void) { return 1; }",
}


def self_test():
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        for rel, text in SELF_TEST.items():
            src = os.path.join(tmp, rel)
            os.makedirs(os.path.dirname(src), exist_ok=True)
            with open(src, "w") as f:
                f.write(text + "\n")
            subprocess.run(["cc", "-c", src, "-o", src[:-2] + ".o"],
                           check=True)
        for lib, objs in (("low", ["a", "c", "d"]), ("high", ["b"]),
                          ("clean", ["c"])):
            d = os.path.join(tmp, "low" if lib == "clean" else lib)
            subprocess.run(["ar", "rcs", os.path.join(d, f"lib{lib}.a")] +
                           [os.path.join(d, o + ".o") for o in objs],
                           check=True)
        layers = [("low", "low/liblow.a"), ("high", "high/libhigh.a")]
        bad = check(tmp, layers, quiet=True)
        clean = check(tmp, [("clean", "low/libclean.a"),
                            ("high", "high/libhigh.a")], quiet=True)
    if bad != 2 or clean != 0:
        print(f"check_layers: self test failed ({bad} problems where 2 "
              f"were planted, {clean} in the clean set)")
        return 1
    return 0


def main():
    if sys.argv[1:2] == ["--self-test"]:
        return self_test()
    if len(sys.argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    if self_test() != 0:
        return 1
    return 1 if check(sys.argv[1], LAYERS, "--graph" in sys.argv[2:],
                      partial="--partial" in sys.argv[2:]) else 0


if __name__ == "__main__":
    sys.exit(main())
