#!/usr/bin/env python3
"""Which functions the code of an interrupt handler runs, inlined ones included (issue #3:
the firmware runs the core's pipeline step and converter drivers, the ones hal-sim runs).

Reads the ELF's machine code with its debug info (release builds keep it):
`llvm-objdump -d --debug-inlined-funcs` names every function inlined at each instruction.
Collects the functions reachable from HANDLER through direct calls plus everything inlined
into them, and fails unless every REQUIRED function (a path without generics, such as
`piezo_core::drivers::ad4000::Ad4000::read`; `a|b` accepts either: when all of an inlined
function's own instructions merged into its callees, objdump names only those) is among them.
Usage: python3 .ci/firmware-code.py ELF HANDLER REQUIRED...
"""
import os
import re
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from elf_tools import thunk_target, tool  # noqa: E402


LEGACY = {"$LT$": "<", "$GT$": ">", "$C$": ",", "$u20$": " ", "$RF$": "&", "$BP$": "*",
          "$u7b$": "{", "$u7d$": "}", "$u5b$": "[", "$u5d$": "]", "$u27$": "'", "$SP$": "@",
          "$u3b$": ";", "$u22$": '"', "$u7e$": "~", "$u2b$": "+"}


def demangle_legacy(s):
    """`_ZN10piezo_core8pipeline...E` -> `piezo_core::pipeline::...` (hash dropped)."""
    if not s.startswith("_ZN"):
        return s
    i, parts = 3, []
    while i < len(s) and s[i].isdigit():
        j = i
        while s[j].isdigit():
            j += 1
        n = int(s[i:j])
        part = s[j:j + n]
        parts.append(part[1:] if part.startswith("_$") else part)
        i = j + n
    if parts and re.fullmatch(r"h[0-9a-f]{16}", parts[-1]):
        parts.pop()
    out = "::".join(parts)
    for k, v in LEGACY.items():
        out = out.replace(k, v)
    return out.replace("..", "::").replace("$", "")


def plain(name):
    """Path without generics and hash: `<a::B<f32, 1>>::step` -> `a::B::step`."""
    name = re.sub(r"::h[0-9a-f]{16}$", "", name)
    m = re.match(r"^<(.*)>::(.*)$", name)
    if m and " as " not in m.group(1):
        name = m.group(1) + "::" + m.group(2)
    out, depth = "", 0
    for ch in name:
        if ch == "<":
            depth += 1
        elif ch == ">":
            depth = max(0, depth - 1)
        elif depth == 0:
            out += ch
    return out


def main():
    elf, handler, required = sys.argv[1], sys.argv[2], sys.argv[3:]
    out = subprocess.check_output([tool("llvm-objdump"), "-d", "--no-show-raw-insn",
                                   "--debug-inlined-funcs=ascii", elf], text=True)
    calls, inlined, cur = {}, {}, None
    for line in out.splitlines():
        m = re.match(r"^[0-9a-f]+ <(.*)>:$", line)
        if m:
            cur = m.group(1)
            calls.setdefault(cur, set())
            inlined.setdefault(cur, set())
            continue
        if cur is None:
            continue
        for name in re.findall(r"(_ZN[0-9A-Za-z_$.]+E|_R[0-9A-Za-z_]+)", line):
            inlined[cur].add(name)
        m = re.search(r"\t(bl|blx|b|b\.w|b\w\w|b\w\w\.w)\s.*<([^>+]+)(\+0x[0-9a-f]+)?>", line)
        if m and m.group(2) != cur:
            calls[cur].add(thunk_target(m.group(2)))
    if handler not in calls:
        sys.exit(f"firmware code: no function {handler} in {elf}")
    seen, todo = set(), [handler]
    while todo:
        f = todo.pop()
        if f not in seen:
            seen.add(f)
            todo.extend(calls.get(f, ()))
    raw = subprocess.check_output([tool("llvm-nm"), "--defined-only", elf], text=True).splitlines()
    dem = subprocess.check_output([tool("llvm-nm"), "--defined-only", "-C", elf], text=True).splitlines()
    pretty = {r.split(maxsplit=2)[-1]: d.split(maxsplit=2)[-1] for r, d in zip(raw, dem) if len(r.split()) == 3}
    names = {plain(pretty.get(f, f)) for f in seen}
    names |= {plain(demangle_legacy(n)) for f in seen for n in inlined.get(f, ())}
    print(f"{os.path.basename(elf)} {handler}: {len(seen)} functions reachable, {len(names)} functions run (inlined included)")
    ok = True
    for r in required:
        hit = [a for a in r.split("|") if a in names]
        print(f"  {r}: {'runs in the handler (' + hit[0] + ')' if hit else 'MISSING'}")
        ok = ok and bool(hit)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
