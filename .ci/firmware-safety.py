#!/usr/bin/env python3
"""Static checks of the H743 firmware ELF: heap, panic paths, stack bound per handler.

Builds the firmware with nightly `-Z emit-stack-sizes` (same link flags as
.cargo/config.toml), then reads the machine code:
  * heap: no `__rust_alloc`/`__rg_alloc`/`__rust_alloc_error_handler` symbol is linked;
  * handlers: every entry of the vector table (read from the ELF's `.vector_table`) except
    Reset; entries that point at the same code are checked once;
  * panic paths: the call graph (direct `bl`/`b` targets from `llvm-objdump -d`) from each
    handler must not reach `rust_begin_unwind` / `core::panicking::*` / the slice index
    failures. A path from ANY handler fails the check; the shortest call chain is printed.
    Reset (init, then idle in thread mode) is reported, not failed: defmt logs only from
    there, so its logger lock is never contended;
  * indirect calls (`blx rN`, `bx rN`, loads into pc) in a handler's reach fail the check:
    they hide callees from the graph and make the stack bound unknown;
  * stack: worst-case stack per handler = max over call paths of the sum of the frames
    from `llvm-readobj --stack-sizes`; recursion, an indirect call or a function without a
    stack record makes the bound unknown, which fails the check.
The worst case of the whole system adds, per preemption level, the largest handler of
that level plus the 104-byte exception frame (FPU state) to thread mode.
Usage: python3 .ci/firmware-safety.py [--no-build] [--features F] [--elf PATH]
"""
import os
import re
import subprocess
import sys
import tomllib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TARGET = "thumbv7em-none-eabihf"
TDIR = os.path.join(ROOT, "target", "stack-sizes")
PANIC = re.compile(r"rust_begin_unwind|panicking|panic_bounds_check|panic_fmt|slice_.*_fail|unwrap_failed|expect_failed|panic_const")
# Leaf routines of the precompiled compiler_builtins carry no stack-size record; they use
# no frame beyond their pushed registers (assumed <= 32 bytes, stated in the output).
BUILTIN = re.compile(r"^(__aeabi_|__udiv|__div|__mod|__umod|__floatun|__float|__fix|memcpy|memmove|memset|memcmp|__addsf|__adddf|__subdf|__muldf|__divdf)|compiler_builtins")
BUILTIN_FRAME = 32
HEAP = re.compile(r"__rust_alloc|__rg_alloc|__rust_alloc_error_handler|__rdl_alloc")
INDIRECT = re.compile(r"\t(blx\s+r\d+|bx\s+r\d+|mov\s+pc,|ldr(\.w)?\s+pc,)")
# Exception entry with lazy FPU stacking: 8 core + 18 FPU words.
EXC_FRAME = 104
# Priorities of the RTIC tasks bound to interrupts (board_h743.rs), for the system bound.
PRIORITY = {"ADC1_2": 3, "TIM2": 3, "USART3": 1}


def tool(name):
    sysroot = subprocess.check_output(["rustc", "--print", "sysroot"], text=True).strip()
    host = next(l.split(": ")[1] for l in subprocess.check_output(["rustc", "-vV"], text=True).splitlines() if l.startswith("host"))
    return os.path.join(sysroot, "lib", "rustlib", host, "bin", name)


def build(features):
    with open(os.path.join(ROOT, ".cargo", "config.toml"), "rb") as f:
        cfg = tomllib.load(f)
    flags = cfg["target"][TARGET].get("rustflags", []) + ["-Z", "emit-stack-sizes"]
    env = dict(os.environ, RUSTFLAGS=" ".join(flags), CARGO_TARGET_DIR=TDIR)
    cmd = ["cargo", "+nightly", "build", "--release", "--target", TARGET, "--bin", "firmware"]
    if features:
        cmd += ["--features", features]
    subprocess.check_call(cmd, cwd=ROOT, env=env)


def symbols(elf):
    """Function address -> name, and mangled -> demangled name."""
    raw = subprocess.check_output([tool("llvm-nm"), "--defined-only", elf], text=True).splitlines()
    dem = subprocess.check_output([tool("llvm-nm"), "--defined-only", "-C", elf], text=True).splitlines()
    addr, pretty = {}, {}
    for r, d in zip(raw, dem):
        pr, pd = r.split(maxsplit=2), d.split(maxsplit=2)
        if len(pr) == 3 and len(pd) == 3:
            pretty[pr[2]] = pd[2]
            if pr[1] in "Tt":
                addr.setdefault(int(pr[0], 16) & ~1, pr[2])
    return addr, pretty


def vector_table(elf, addr):
    """Handler names of the vector table (entry 1 = Reset onwards), deduplicated."""
    out = subprocess.check_output([tool("llvm-objdump"), "-s", "-j", ".vector_table", elf], text=True)
    words = []
    for line in out.splitlines():
        m = re.match(r"^ ([0-9a-f]+) ((?:[0-9a-f]{8} ?){1,4})", line)
        if m:
            words += [int.from_bytes(bytes.fromhex(w), "little") for w in m.group(2).split()]
    names = []
    for w in words[1:]:
        n = addr.get(w & ~1)
        if w and n and n not in names:
            names.append(n)
    return names


def stack_sizes(elf):
    out = subprocess.run([tool("llvm-readobj"), "--stack-sizes", elf], capture_output=True, text=True).stdout
    sizes, fn = {}, None
    for line in out.splitlines():
        m = re.search(r"Functions: \[(.*)\]", line)
        if m:
            fn = m.group(1)
        m = re.search(r"Size: (0x[0-9a-fA-F]+|\d+)", line)
        if m and fn:
            for name in fn.split(", "):
                sizes[name.strip()] = int(m.group(1), 0)
            fn = None
    return sizes


def call_graph(elf):
    # Mangled names: demangled generics contain '<', '>' and ', ' that break the parse.
    out = subprocess.check_output([tool("llvm-objdump"), "-d", "--no-show-raw-insn", elf], text=True)
    graph, indirect, cur = {}, {}, None
    for line in out.splitlines():
        m = re.match(r"^[0-9a-f]+ <(.*)>:$", line)
        if m:
            cur = m.group(1)
            graph.setdefault(cur, set())
            continue
        if cur is None:
            continue
        m = re.search(r"\t(bl|blx|b|b\.w|bx|b\w\w|b\w\w\.w|cbz|cbnz)\s.*<([^>+]+)(\+0x[0-9a-f]+)?>", line)
        if m and m.group(2) != cur:
            graph[cur].add(m.group(2))
        elif INDIRECT.search(line) and not re.search(r"\tbx\s+lr", line):
            indirect.setdefault(cur, line.split("\t", 1)[-1].strip())
    return graph, indirect


def main():
    args = sys.argv[1:]
    features = args[args.index("--features") + 1] if "--features" in args else ""
    elf = args[args.index("--elf") + 1] if "--elf" in args else os.path.join(TDIR, TARGET, "release", "firmware")
    if "--no-build" not in args and "--elf" not in args:
        build(features)
    addr, pretty = symbols(elf)
    name = lambda f: pretty.get(f, f)
    syms = subprocess.check_output([tool("llvm-nm"), elf], text=True)
    heap = sorted({l.split()[-1] for l in syms.splitlines() if HEAP.search(l)})
    print(f"firmware: {os.path.relpath(elf, ROOT)}{' (features ' + features + ')' if features else ''}")
    print(f"heap: {'none linked' if not heap else 'LINKED: ' + ', '.join(heap)}")
    graph, indirect = call_graph(elf)
    sizes = stack_sizes(elf)
    # Thread mode (Reset -> main: init, then idle) first, then the exception/interrupt handlers.
    handlers = vector_table(elf, addr)
    handlers = ["main" if "main" in graph else handlers[0]] + handlers[1:]
    ok = not heap

    def reach(root):
        """Reachable functions with the caller that first reached each (BFS: shortest chains)."""
        parent, todo = {root: None}, [root]
        while todo:
            nxt = []
            for f in todo:
                for g in sorted(graph.get(f, ())):
                    if g not in parent:
                        parent[g] = f
                        nxt.append(g)
            todo = nxt
        return parent

    def chain(parent, f):
        out = []
        while f is not None:
            out.append(name(f))
            f = parent[f]
        return " -> ".join(reversed(out))

    memo = {}

    def worst(f, path):
        """Worst-case stack from f; None when unknown (recursion, indirect call, no size)."""
        if f in path:
            return None
        if f in memo:
            return memo[f]
        own = sizes.get(f)
        if own is None and BUILTIN.search(f):
            own = BUILTIN_FRAME
        if own is None or f in indirect:
            memo[f] = None
            return None
        best, via = 0, None
        for g in sorted(graph.get(f, ())):
            w = worst(g, path | {f})
            if w is None:
                memo[f] = None
                return None
            if w > best:
                best, via = w, g
        memo[f] = own + best
        deepest[f] = via
        return memo[f]

    deepest = {}

    def frames(f):
        """The deepest call chain from f with each frame's size."""
        out = []
        while f is not None:
            out.append(f"{name(f)} {sizes.get(f, BUILTIN_FRAME)}")
            f = deepest.get(f)
        return " -> ".join(out)

    rows = []
    for h in handlers:
        r = reach(h)
        panics = sorted(f for f in r if PANIC.search(f))
        ind = sorted(f for f in r if f in indirect)
        w = worst(h, frozenset())
        thread = h == handlers[0]
        rows.append((h, len(r), panics, ind, w, thread))
        if not thread and (panics or ind or w is None):
            ok = False

    print(f"{'handler':<34} {'reachable fns':>13} {'panic path':>10} {'indirect':>8} {'stack (bytes)':>14}")
    for h, n, panics, ind, w, thread in rows:
        label = (name(h) + " (thread: init, idle)") if thread else name(h)
        print(f"{label[:34]:<34} {n:>13} {('YES' if panics else 'none'):>10} {len(ind):>8} {('unknown' if w is None else w):>14}")
    for h, n, panics, ind, w, thread in rows:
        if w is not None and n > 1:
            print(f"{name(h)}: deepest stack: {frames(h)}")
    for h, n, panics, ind, w, thread in rows:
        if not (panics or ind or w is None):
            continue
        r = reach(h)
        print(f"{name(h)}{' (thread mode: reported, not failed)' if thread else ':'}")
        for p in panics[:4]:
            print(f"  panic path: {chain(r, p)}")
        for f in ind[:4]:
            print(f"  indirect call `{indirect[f]}` in: {chain(r, f)}")
        if w is None:
            missing = sorted(f for f in r if f not in sizes and not BUILTIN.search(f))
            if missing:
                print(f"  no stack record: {', '.join(name(f) for f in missing[:6])}")
    # System bound: thread mode + per priority level the largest handler + exception frame.
    levels = {}
    for h, n, panics, ind, w, thread in rows:
        if thread or h not in PRIORITY or w is None:
            continue
        levels[PRIORITY[h]] = max(levels.get(PRIORITY[h], 0), w)
    base = rows[0][4] if rows else None
    if base is not None and levels:
        total = base + sum(v + EXC_FRAME for v in levels.values())
        print(f"worst-case stack, all levels nested (thread mode {base} B + per level handler + {EXC_FRAME} B frame): {total} bytes")
    print(f"(compiler_builtins leaf routines counted as {BUILTIN_FRAME} bytes each)")
    print(f"firmware safety: {'PASS' if ok else 'FAIL'}")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
