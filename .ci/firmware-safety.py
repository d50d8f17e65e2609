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
  * indirect calls (`blx rN`, `bx rN`, loads into pc) in a handler's reach fail the check.
    In thread mode they are resolved conservatively: a site whose register, on every path
    back, comes from movw/movt constants of its own function calls only those functions;
    any other site may call every address-taken function (start address with the Thumb
    bit found as a word anywhere in the flash image except the vector table, as a movw/movt
    pair, or as an `adr` target). The script prints each site's candidates;
  * stack: worst-case stack per handler/task = max over call paths of the sum of the
    frames from `llvm-readobj --stack-sizes`; recursion (also through indirect-call
    candidates) or a function without a stack record makes the bound unknown, which fails
    the check for a handler. Thread mode is reported per task (init, idle), with and
    without its panic paths (panic-probe logs through core::fmt, whose candidate set
    recurses, then halts).
  * HardFault entry: MSP set to the vector table's initial SP before any instruction
    touches the stack (also with --itcm-only).
The worst case of the whole system: init runs alone (interrupts off until its last
instruction); afterwards thread mode (idle, or init's own frame before it returns) plus,
per preemption level, the largest handler of that level and the 104-byte exception frame.
Usage: python3 .ci/firmware-safety.py [--no-build] [--features F] [--elf PATH]
"""
import os
import re
import struct
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from elf_tools import thunk_target, tool  # noqa: E402
import tomllib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TARGET = "thumbv7em-none-eabihf"
TDIR = os.path.join(ROOT, "target", "stack-sizes")
PANIC = re.compile(r"rust_begin_unwind|panicking|panic_bounds_check|panic_fmt|slice_.*_fail|unwrap_failed|expect_failed|panic_const")
# Leaf routines of the precompiled compiler_builtins carry no stack-size record; they use
# no frame beyond their pushed registers (assumed <= 32 bytes, stated in the output).
BUILTIN = re.compile(r"^(__aeabi_|__udiv|__div|__mod|__umod|__floatun|__float|__fix|memcpy|memmove|memset|memcmp|__addsf|__adddf|__subdf|__muldf|__divdf)|compiler_builtins")
BUILTIN_FRAME = 32
# Made by the linker, no frame: a range-extension thunk (a jump to its target) and the label
# of the ITCM section's padding words (build.rs), which is no code.
PAD = re.compile(r"\tbmi\s+0x[0-9a-f]+ <[^>]*> @ imm = #-0x58$")
LINKER = re.compile(r"^(__\w*LongThunk_.+|__sitcm)$")
HEAP = re.compile(r"__rust_alloc|__rg_alloc|__rust_alloc_error_handler|__rdl_alloc")
INDIRECT = re.compile(r"\t(blx\s+r\d+|bx\s+r\d+|mov\s+pc,|ldr(\.w)?\s+pc,)")
# Exception entry with lazy FPU stacking: 8 core + 18 FPU words.
EXC_FRAME = 104
# Priorities of the RTIC tasks bound to interrupts (src/bin/h743/main.rs), for the system bound.
# A control interrupt is one that reaches the pipeline's step (on-chip converters and xy:
# ADC1_2; spi-converters: TIM2).
CONTROL = re.compile(r"piezo_core::pipeline::Pipeline\W.*::step(::h[0-9a-f]{16})?$")
# Entered from the control interrupt only once after a fault or a configuration change
# (`Pipeline::restart`, and `Pipeline::settle_pending`, which runs it or decides the fused
# path once after the law primed or was changed; both #[cold]): they and what only they
# reach may stay in flash (ITCM is 64 KB and the two-axis build's per-sample code alone
# nearly fills it).
COLD = re.compile(r"piezo_core::pipeline::Pipeline\W.*::(restart|settle_pending)(::h[0-9a-f]{16})?$")
# The NMI (-2) and HardFault (-1) preempt every configurable level: their stacks add on top,
# except a HardFault that first moves MSP to the stack's top (checked: `hardfault_entry`).
PRIORITY = {"ADC1_2": 3, "TIM2": 3, "USART3": 1, "NonMaskableInt": -2, "HardFault": -1}


def build(features):
    with open(os.path.join(ROOT, ".cargo", "config.toml"), "rb") as f:
        cfg = tomllib.load(f)
    # The H743 build's own flag (`cargo h743`, .cargo/config.toml's alias).
    flags = cfg["target"][TARGET].get("rustflags", []) + ["-C", "target-cpu=cortex-m7", "-Z", "emit-stack-sizes"]
    env = dict(os.environ, RUSTFLAGS=" ".join(flags), CARGO_TARGET_DIR=TDIR)
    cmd = ["cargo", "+nightly", "build", "--release", "--target", TARGET, "--bin", "h743"]
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
    graph, indirect, consts, code, cur = {}, {}, {}, {}, None
    lo, hi, pad = set(), set(), []
    for line in out.splitlines():
        m = re.match(r"^[0-9a-f]+ <(.*)>:$", line)
        if m:
            if cur is not None:
                consts[cur] = {h << 16 | low for h in hi for low in lo}
            lo, hi, pad = set(), set(), []
            cur = m.group(1)
            graph.setdefault(cur, set())
            continue
        if cur is None:
            continue
        m = re.search(r"\tmov([wt])\s+r\d+, #(0x[0-9a-f]+|\d+)", line)
        if m:
            (lo if m.group(1) == "w" else hi).add(int(m.group(2), 0))
        m = re.search(r"\t(bl|blx|b|b\.w|bx|b\w\w|b\w\w\.w|cbz|cbnz)\s.*<([^>+]+)(\+0x[0-9a-f]+)?>", line)
        # A branch into the middle of another function is no call: it is alignment padding
        # after a function's last branch that happens to decode as a branch (seen after
        # h743::safe::halt's `wfi` loop: `bmi <h743::app::idle+0x15e>`).
        # lld fills the gap after a function with 0xd4d4 (Thumb `bmi #-0x58`): a run of those
        # ending the function is padding, whatever function it seems to branch to (seen after
        # h743::safe::halt: `bmi <NonMaskableInt>`, a false cycle halt -> NMI -> halt).
        if PAD.search(line):
            if m and m.group(2) != cur and m.group(3) is None:
                pad.append(thunk_target(m.group(2)))
        elif re.match(r"^\s*[0-9a-f]+:", line):
            graph[cur].update(pad)
            pad = []
            if m and m.group(2) != cur and m.group(3) is None:
                graph[cur].add(thunk_target(m.group(2)))
        m = re.match(r"^\s*([0-9a-f]+):\s*\t(\S+)\s*([^@]*)", line)
        if m and m.group(2).startswith("adr"):  # pc-relative address: counted as taken
            t = ((int(m.group(1), 16) + 4) & ~3) + int(m.group(3).split("#")[1].split()[0], 0)
            consts.setdefault("<adr>", set()).update({t, t | 1})
        elif m and re.match(r"(add|sub)", m.group(2)) and re.search(r",\s*pc\b", m.group(3)):
            consts.setdefault("<pc-relative>", set()).add(int(m.group(1), 16))
        if m:
            code.setdefault(cur, []).append((int(m.group(1), 16), m.group(2), m.group(3).strip()))
        if INDIRECT.search(line) and not re.search(r"\tbx\s+lr", line) and not re.search(r"\t(bl|b)\s.*<", line):
            indirect.setdefault(cur, []).append(line.split("\t", 1)[-1].strip())
    consts[cur] = {h << 16 | low for h in hi for low in lo}
    for f in graph:
        if LINKER.match(f):
            graph[f] = {thunk_target(f)} - {f}
            indirect.pop(f, None)
    local = {f: local_targets(code.get(f, [])) for f in indirect}
    return graph, indirect, consts, local, code


# Instructions that write no core register other than through base writeback.
NOWRITE = re.compile(r"^(str|cmp|cmn|tst|teq|cbn?z|push|it|dmb|dsb|isb|nop|cps|msr|vstr|vpush|vcmp|wfi|udf|bkpt"
                     r"|b(l|x|lx)?(eq|ne|cs|cc|hs|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le|al)?(\.w|\.n)?$)")


def local_targets(code):
    """Constants every indirect call of a function can hold, or None. Per site, walks back
    over all paths (branch sources and fall-through) from the call to the writes of its
    register: movw/movt give the value, `mov rN, rM` follows rM, `mov<cond> rN, rM` follows
    both; reaching the entry or any other write of a followed register gives up."""
    where = {a: k for k, (a, _, _) in enumerate(code)}
    ends = lambda mn, ops: mn in ("b", "b.w", "bx") or mn in ("pop", "pop.w") and "pc" in ops or mn.startswith(("ldr", "mov")) and ops.startswith("pc,")
    # Reachable instructions (bytes after a return can decode as stray branches).
    live, todo = set(), [0] if code else []
    while todo:
        k = todo.pop()
        if k in live or k >= len(code):
            continue
        live.add(k)
        a, mn, ops = code[k]
        if re.match(r"tb[bh]", mn):
            return None
        if re.match(r"(b|cb)", mn):
            todo += [where[int(t, 16)] for t in re.findall(r"0x([0-9a-f]+) <", ops) if int(t, 16) in where]
        if not ends(mn, ops):
            todo.append(k + 1)
    srcs = {}
    for k in live:
        a, mn, ops = code[k]
        if re.match(r"(b|cb)", mn):
            for t in re.findall(r"0x([0-9a-f]+) <", ops):
                srcs.setdefault(int(t, 16), []).append(k)

    def preds(k):
        out = [where[0] for _ in ()] + srcs.get(code[k][0], [])
        if k > 0 and k - 1 in live and not ends(*code[k - 1][1:]):
            out.append(k - 1)
        return out

    found = set()
    for i in sorted(live):
        at, mn, ops = code[i]
        if not INDIRECT.search(f"\t{mn} {ops}") or mn == "bx" and ops == "lr":
            continue
        if not re.fullmatch(r"blx|bx", mn):
            return None
        states, seen = [(p, ops, None) for p in preds(i)], set()
        if not states:
            return None
        while states:
            k, r, hi = states.pop()
            if (k, r, hi) in seen:
                continue
            seen.add((k, r, hi))
            if len(seen) > 20000:
                return None
            a, m, o = code[k]
            regs = re.findall(r"\b(r\d+|sp|lr|pc)\b", o)
            nxt = [(p, r, hi) for p in preds(k)]
            if r in regs and (regs[0] == r and not NOWRITE.match(m) or re.search(r"!|\], #|^(ldm|pop|ldrd|umull|smull|umlal|smlal|vmov)", m + " " + o)):
                if m == "movt" and hi is None:
                    nxt = [(p, r, int(o.split("#")[-1], 0)) for p in preds(k)]
                elif m == "movw":
                    found.add((hi or 0) << 16 | int(o.split("#")[-1], 0))
                    nxt = []
                elif m in ("mov", "mov.w") and len(regs) == 2 and hi is None:
                    nxt = [(p, regs[1], None) for p in preds(k)]
                elif re.fullmatch(r"mov(eq|ne|cs|cc|hs|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le)", m) and len(regs) == 2 and hi is None:
                    nxt += [(p, regs[1], None) for p in preds(k)]
                else:
                    return None
            elif not nxt:
                return None  # function entry with the register still open
            states += nxt
    return found

def sections(elf):
    """(name, type, flags, address, file offset, size) of every section."""
    with open(elf, "rb") as f:
        data = f.read()
    shoff, = struct.unpack_from("<I", data, 0x20)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 0x2E)
    secs = [struct.unpack_from("<10I", data, shoff + i * shentsize) for i in range(shnum)]
    strtab = secs[shstrndx][4]
    out = []
    for name_off, typ, flags, address, off, size, *_ in secs:
        out.append((data[strtab + name_off:data.index(b"\0", strtab + name_off)].decode(), typ, flags, address, off, size))
    return data, out


def word_at(elf, address):
    """The 32-bit word the image holds at `address` (None outside its loaded bytes)."""
    data, secs = sections(elf)
    for name, typ, flags, at, off, size in secs:
        if typ != 8 and flags & 2 and at <= address and address + 4 <= at + size:  # not NOBITS
            return int.from_bytes(data[off + address - at:off + address - at + 4], "little")
    return None


def hardfault_entry(elf, code):
    """Issue 27 item 3: the HardFault moves MSP to a known-good stack (the vector table's
    initial SP) before any instruction touches the stack, since a stack overflow enters it
    with SP at the RAM's edge and a fault inside it locks the core up. Returns (ok, why)."""
    ins = code.get("HardFault", [])
    loaded = {}
    for at, mn, ops in ins:
        if mn == "msr" and ops.replace(" ", "").startswith("msp,"):
            reg = ops.split(",")[1].strip()
            initial = word_at(elf, next(a for n, t, f, a, o, sz in sections(elf)[1] if n == ".vector_table"))
            if reg not in loaded:
                return False, f"`msr msp, {reg}` with {reg} not loaded from a literal"
            if loaded[reg] != initial:
                return False, f"MSP set to {loaded[reg]:#x}, the vector table's initial SP is {initial:#x}"
            return True, f"MSP = {initial:#x} (the initial SP) before any stack use"
        m = re.fullmatch(r"(r\d+), \[pc, #(-?0x[0-9a-f]+|-?\d+)\].*", ops)
        if mn in ("ldr", "ldr.w") and m:
            loaded[m.group(1)] = word_at(elf, ((at + 4) & ~3) + int(m.group(2), 0))
            continue
        return False, f"`{mn} {ops}` before MSP is set to a known-good stack"
    return False, "no `msr msp` in the HardFault entry" if ins else "no HardFault symbol"


def address_taken(elf, addr, consts):
    """Functions whose start address (Thumb bit set) can reach a register other than by a
    direct branch: as a 32-bit word at any byte offset of an allocated section except the
    vector table (literal pools, vtables, fmt::Arguments, statics), or as a movw/movt pair
    of one function (every low half combined with every high half, a superset of the
    pairs). Only such a function can be the target of `blx rN`."""
    data, secs = sections(elf)
    words = set().union(*consts.values())
    for nm, typ, flags, _, off, size in secs:
        # SHT_PROGBITS with SHF_ALLOC: the bytes in flash (.data holds its initial values).
        if typ != 1 or not flags & 2 or nm == ".vector_table":
            continue
        blob = data[off:off + size]
        words |= {int.from_bytes(blob[i:i + 4], "little") for i in range(len(blob) - 3)}
    if consts.get("<pc-relative>"):  # add rN, pc: addresses not seen as constants
        return sorted(addr.values())
    return sorted(f for a, f in addr.items() if a | 1 in words)


def main():
    args = sys.argv[1:]
    features = args[args.index("--features") + 1] if "--features" in args else ""
    elf = args[args.index("--elf") + 1] if "--elf" in args else os.path.join(TDIR, TARGET, "release", "h743")
    if "--no-build" not in args and "--elf" not in args:
        build(features)
    addr, pretty = symbols(elf)
    name = lambda f: pretty.get(f, f)
    syms = subprocess.check_output([tool("llvm-nm"), elf], text=True)
    heap = sorted({l.split()[-1] for l in syms.splitlines() if HEAP.search(l)})
    print(f"firmware: {os.path.relpath(elf, ROOT)}{' (features ' + features + ')' if features else ''}")
    print(f"heap: {'none linked' if not heap else 'LINKED: ' + ', '.join(heap)}")
    graph, indirect, consts, local, code_of = call_graph(elf)
    cand = address_taken(elf, addr, consts)
    # A function whose every indirect call takes its register from movw/movt constants of
    # its own straight-line code calls only those; others may call any address-taken one.
    targets = lambda f: cand if local.get(f) is None or not local[f] <= {a | 1 for a in addr} else sorted(addr[a & ~1] for a in local[f])
    addr_of = {f: a for a, f in addr.items()}
    sizes = stack_sizes(elf)
    fresh, why = hardfault_entry(elf, code_of)
    print(f"HardFault entry: {'PASS' if fresh else 'FAIL'}: {why}")
    if fresh:
        sizes["HardFault"] = 0  # the assembly entry: no push before its branch
    # Thread mode (Reset -> main: init, then idle) first, then the exception/interrupt handlers.
    handlers = vector_table(elf, addr)
    handlers = ["main" if "main" in graph else handlers[0]] + handlers[1:]
    ok = not heap and fresh

    def reach(root):
        """Reachable functions with the caller that first reached each (BFS: shortest chains)."""
        parent, todo = {root: None}, [root]
        while todo:
            nxt = []
            for f in todo:
                for g in sorted(graph.get(f, set()) | (set(targets(f)) if f in indirect else set())):
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

    def worst(f, path, nopanic=False):
        """Worst-case stack from f; None when unknown (recursion, indirect call, no size)."""
        if f in path:
            return None
        if (f, nopanic) in memo:
            return memo[f, nopanic]
        own = sizes.get(f)
        if own is None and BUILTIN.search(f):
            own = BUILTIN_FRAME
        if own is None and LINKER.match(f):
            own = 0
        if own is None:
            memo[f, nopanic] = None
            return None
        best, via = 0, None
        # An indirect call may reach any address-taken function.
        for g in sorted(graph.get(f, set()) | (set(targets(f)) if f in indirect else set())):
            if nopanic and PANIC.search(g):
                continue
            w = worst(g, path | {f}, nopanic)
            if w is None:
                memo[f, nopanic] = None
                return None
            if w > best:
                best, via = w, g
        memo[f, nopanic] = own + best
        deepest[f] = via
        return memo[f, nopanic]

    deepest = {}

    def frames(f):
        """The deepest call chain from f with each frame's size."""
        out = []
        while f is not None:
            out.append(f"{name(f)} {sizes.get(f, 0 if LINKER.match(f) else BUILTIN_FRAME)}")
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

    # ITCM, checked (build.rs's `.itcm` patterns name functions by their symbols, and a
    # symbol scheme the patterns miss leaves code in flash without a word): every function a
    # control interrupt reaches (thunks followed) lies in ITCM, and __pre_init, which loads
    # ITCM before anything runs, lies in flash.
    itcm_hi = 0x0001_0000
    if "--itcm-only" in args:  # a build without stack sizes (the release build's own ELF)
        ok = not heap and fresh
    for h in handlers[1:]:
        if not any(CONTROL.search(name(f)) for f in reach(h)):
            continue
        hot, todo = {h}, [h]
        while todo:
            f = todo.pop()
            for g in graph.get(f, set()) | (set(targets(f)) if f in indirect else set()):
                if g not in hot and not COLD.search(name(g)):
                    hot.add(g)
                    todo.append(g)
        in_flash = lambda fs: sorted(name(f) for f in fs if f in addr_of and addr_of[f] >= itcm_hi and not LINKER.match(f))
        far, cold = in_flash(hot), set(reach(h)) - hot
        print(f"{name(h)}: {len(hot) - len(far)} functions of the per-sample path in ITCM, {len(far)} in flash;"
              f" {len(cold)} more behind the restart and the pending settle (cold), {len(in_flash(cold))} of them in flash")
        for f in far[:int(os.environ.get("ITCM_LIST", "12"))]:
            print(f"  in flash: {f}")
        ok = ok and not far
    if "__eitcm" in addr_of and "__sitcm" in addr_of:
        print(f"ITCM: {addr_of['__eitcm'] - addr_of['__sitcm']} of {itcm_hi - 8} bytes used")
    pre = addr_of.get("__pre_init")
    if pre is None or pre < itcm_hi:
        print(f"__pre_init: {'missing' if pre is None else 'in ITCM'} (it must load ITCM from flash)")
        ok = False
    if "--itcm-only" in args:
        print(f"firmware ITCM: {'PASS' if ok else 'FAIL'}")
        sys.exit(0 if ok else 1)
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
            print(f"  indirect call `{indirect[f][0]}` in: {chain(r, f)}")
        if w is None:
            missing = sorted(f for f in r if f not in sizes and not BUILTIN.search(f) and not LINKER.match(f))
            if missing:
                print(f"  no stack record: {', '.join(name(f) for f in missing[:6])}")
    # Indirect calls: every site may reach any address-taken function (sound, not precise).
    sites = {f: len(v) for f, v in indirect.items() if f in reach(handlers[0])}
    print(f"address-taken functions ({len(cand)}): {', '.join(name(f) for f in cand)}")
    for f in sorted(sites, key=name):
        t = targets(f)
        print(f"indirect calls: {sites[f]} site(s) in {name(f)} -> {len(t)} candidate target(s)"
              f"{': ' + ', '.join(name(g) for g in t) if t != cand else ' (all address-taken)'}")
    # Per task. RTIC's main runs init (in __rtic_init_resources, interrupts disabled until its
    # last instruction `cpsie i`, before its epilogue) and then idle; sizes include main's frame.
    fmt = lambda v: "unknown" if v is None else f"{v} B"
    calls = sorted(graph.get("main", ()))
    init = next((g for g in calls if "__rtic_init_resources" in name(g)), None)
    idle = next((g for g in calls if name(g).endswith("::idle")), None)
    tasks = {}
    own_main = sizes.get("main")
    # Panic paths end in panic-probe (log, then halt); the "no panic" bounds hold up to the
    # call of the panic entry point.
    for label, f in (("init", init), ("idle", idle)):
        for np in (False, True):
            w = worst(f, frozenset({"main"}), np) if f and own_main is not None else None
            tasks[label, np] = None if w is None else own_main + w
    init_own = sizes.get(init) if init else None
    levels = {}
    for h, n, panics, ind, w, thread in rows:
        # A HardFault that moves to the stack's top first does not nest: it starts over.
        if thread or h not in PRIORITY or h == "HardFault" and fresh:
            continue
        levels[PRIORITY[h]] = None if w is None or levels.get(PRIORITY[h], 0) is None else max(levels.get(PRIORITY[h], 0), w)
    print("stack per task (bytes):")
    print(f"  thread mode, main as a whole: {fmt(rows[0][4])}")
    for t in ("init", "idle"):
        print(f"  {t} (with main's {own_main} B): {fmt(tasks[t, False])}; without panic paths: {fmt(tasks[t, True])}")
    for h, n, panics, ind, w, thread in rows[1:]:
        print(f"  {name(h)}{' (priority ' + str(PRIORITY[h]) + ')' if h in PRIORITY else ''}: {fmt(w)}")
    # Handlers nest on thread mode once interrupts are on: during idle, or in the epilogue
    # of __rtic_init_resources (its own frame still allocated). Init itself runs unpreempted.
    for np in (False, True):
        nested = total = None
        if None not in levels.values() and tasks["idle", np] is not None and init_own is not None:
            nested = max(tasks["idle", np], own_main + init_own) + sum(v + EXC_FRAME for v in levels.values())
            total = None if tasks["init", np] is None else max(nested, tasks["init", np])
            hf = next((w for h, n, p, i, w, t in rows if h == "HardFault"), 0) if fresh else 0
            total = None if total is None or hf is None else max(total, hf)
        print(f"worst-case stack, whole system{' without thread-mode panic paths' if np else ''}: {fmt(total)}"
              f" (interrupts on: max(idle, main+init frame {own_main + (init_own or 0)}) + per level handler"
              f" + {EXC_FRAME} B frame = {fmt(nested)}; init runs with interrupts off)")
    print(f"(compiler_builtins leaf routines counted as {BUILTIN_FRAME} bytes each)")
    print(f"firmware safety: {'PASS' if ok else 'FAIL'}")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
