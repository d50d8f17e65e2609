#!/usr/bin/env python3
"""Static checks of the H743 firmware ELF: heap, panic paths, stack bound per task.

Builds the firmware with nightly `-Z emit-stack-sizes` (same link flags as
.cargo/config.toml), then reads the machine code:
  * heap: no `__rust_alloc`/`__rg_alloc`/`__rust_alloc_error_handler` symbol is linked;
  * panic paths: the call graph (direct `bl`/`b` targets from `llvm-objdump -d`) from the
    control interrupt (ADC1_2) must not reach `rust_begin_unwind` / `core::panicking::*`;
    the other handlers (serial, monotonic, RTIC dispatchers) are reported;
  * stack: worst-case stack per handler = max over call paths of the sum of the frames
    from `llvm-readobj --stack-sizes`; recursion or an indirect call makes the bound
    unknown and is reported as such.
Usage: python3 .ci/firmware-safety.py [--no-build]
"""
import os
import re
import subprocess
import sys
import tomllib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TARGET = "thumbv7em-none-eabihf"
TDIR = os.path.join(ROOT, "target", "stack-sizes")
ELF = os.path.join(TDIR, TARGET, "release", "firmware")
HANDLERS = ["ADC1_2", "USART3", "SysTick", "SAI1", "SAI2"]
# The control interrupt must have no panic path (hard failure); the others are reported.
CONTROL = "ADC1_2"
PANIC = re.compile(r"rust_begin_unwind|panicking|panic_bounds_check|panic_fmt|slice_.*_fail|unwrap_failed|expect_failed")
# Leaf routines of the precompiled compiler_builtins carry no stack-size record; they use
# no frame beyond their pushed registers (assumed <= 32 bytes, stated in the output).
BUILTIN = re.compile(r"^(__aeabi_|memcpy|memmove|memset|memcmp)|compiler_builtins")
BUILTIN_FRAME = 32
HEAP = re.compile(r"__rust_alloc|__rg_alloc|__rust_alloc_error_handler|__rdl_alloc")


def tool(name):
    sysroot = subprocess.check_output(["rustc", "--print", "sysroot"], text=True).strip()
    host = next(l.split(": ")[1] for l in subprocess.check_output(["rustc", "-vV"], text=True).splitlines() if l.startswith("host"))
    return os.path.join(sysroot, "lib", "rustlib", host, "bin", name)


def build():
    with open(os.path.join(ROOT, ".cargo", "config.toml"), "rb") as f:
        cfg = tomllib.load(f)
    flags = cfg["target"][TARGET].get("rustflags", []) + ["-Z", "emit-stack-sizes"]
    env = dict(os.environ, RUSTFLAGS=" ".join(flags), CARGO_TARGET_DIR=TDIR)
    subprocess.check_call(["cargo", "+nightly", "build", "--release", "--target", TARGET, "--bin", "firmware"], cwd=ROOT, env=env)


def stack_sizes():
    out = subprocess.run([tool("llvm-readobj"), "--stack-sizes", ELF], capture_output=True, text=True).stdout
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


def call_graph():
    # Mangled names: demangled generics contain '<', '>' and ', ' that break the parse.
    out = subprocess.check_output([tool("llvm-objdump"), "-d", "--no-show-raw-insn", ELF], text=True)
    graph, indirect, cur = {}, set(), None
    for line in out.splitlines():
        m = re.match(r"^[0-9a-f]+ <(.*)>:$", line)
        if m:
            cur = m.group(1)
            graph.setdefault(cur, set())
            continue
        if cur is None:
            continue
        m = re.search(r"\t(bl|blx|b|b\.w|bx)\s.*<([^>+]+)(\+0x[0-9a-f]+)?>", line)
        if m and m.group(2) != cur:
            graph[cur].add(m.group(2))
        elif re.search(r"\tblx\s+r\d", line):
            indirect.add(cur)
    return graph, indirect


def main():
    if "--no-build" not in sys.argv:
        build()
    syms = subprocess.check_output([tool("llvm-nm"), ELF], text=True)
    heap = sorted({l.split()[-1] for l in syms.splitlines() if HEAP.search(l)})
    print(f"heap: {'none linked' if not heap else 'LINKED: ' + ', '.join(heap)}")
    graph, indirect = call_graph()
    sizes = stack_sizes()
    ok = not heap

    def reach(root):
        seen, todo = set(), [root]
        while todo:
            f = todo.pop()
            if f in seen:
                continue
            seen.add(f)
            todo.extend(graph.get(f, ()))
        return seen

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
        best = 0
        for g in graph.get(f, ()):
            w = worst(g, path | {f})
            if w is None:
                memo[f] = None
                return None
            best = max(best, w)
        memo[f] = own + best
        return memo[f]

    print(f"{'handler':<18} {'reachable fns':>13} {'panic path':>10} {'stack (bytes)':>14}")
    for h in HANDLERS:
        if h not in graph:
            continue
        r = reach(h)
        panics = sorted(f for f in r if PANIC.search(f))
        w = worst(h, frozenset())
        print(f"{h:<18} {len(r):>13} {('YES' if panics else 'no'):>10} {('unknown' if w is None else w):>14}")
        if panics:
            ok = ok and h != CONTROL
            print(f"  reaches: {', '.join(panics[:5])}")
        if w is None:
            why = sorted(f for f in r if f in indirect or (f not in sizes and not BUILTIN.search(f)))
            print(f"  unknown because of indirect calls or missing frames in: {', '.join(why[:6])}")
    print(f"(compiler_builtins leaf routines counted as {BUILTIN_FRAME} bytes each)")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
