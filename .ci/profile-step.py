#!/usr/bin/env python3
"""Where the main mode's instructions go: a per-block profile of the control step on the M4F
under QEMU (issue 27 item 7; docs/src/design.md, "Where the instructions go"). Not a CI step.

Builds the QEMU board with `PIEZO_BENCH_ONLY="<law> <ff>"` (the bench runs that row only and
brackets its 2000 timed steps with two calls of `bench::mark`), runs it with
`-singlestep -d exec,nochain` (one log line per executed instruction), counts the program
counters between the two marks and maps them with `llvm-symbolizer --inlining`. Prints the
instructions per step by block (the function inlined directly into the fused step or into the
robust law's update) and by innermost function.

    python3 .ci/profile-step.py                      # ff+hgo-robust on ims-cbw
    python3 .ci/profile-step.py --row "ff+hgo-robust linear" --keep /tmp/prof

Needs qemu-system-arm and llvm-symbolizer on PATH; about two minutes and 1 GB of log
(deleted unless --keep).
"""
import argparse
import collections
import os
import re
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import elf_tools  # noqa: E402

STEPS = 2000  # bench::BENCH_STEPS
TARGET = "thumbv7em-none-eabihf"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--row", default="ff+hgo-robust ims-cbw", help='"<law> <feedforward>"')
    ap.add_argument("--keep", help="keep the ELF and the execution log in this directory")
    ap.add_argument("--top", type=int, default=25, help="innermost functions listed")
    a = ap.parse_args()
    for t in ("qemu-system-arm", "llvm-symbolizer"):
        if shutil.which(t) is None:
            sys.exit(f"profile-step: {t} not found on PATH")
    work = a.keep or tempfile.mkdtemp(prefix="profile-step-")
    os.makedirs(work, exist_ok=True)
    try:
        profile(a, work)
    finally:
        if not a.keep:
            shutil.rmtree(work, ignore_errors=True)


def profile(a, work):
    """Build, run and count in `work`."""
    target_dir = os.path.join(work, "target")
    env = dict(os.environ, PIEZO_BENCH_ONLY=a.row, CARGO_TARGET_DIR=target_dir)
    subprocess.run(["cargo", "build", "-q", "--release", "--target", TARGET, "-p", "piezo-core",
                    "--bin", "qemu"], env=env, check=True)
    elf = os.path.join(target_dir, TARGET, "release", "qemu")
    log = os.path.join(work, "exec.log")
    # The board answers `bench` with the table and exits after it in this build.
    subprocess.run(["qemu-system-arm", "-M", "mps2-an386", "-cpu", "cortex-m4", "-nographic",
                    "-monitor", "none", "-icount", "shift=0,sleep=off", "-serial", "stdio",
                    "-semihosting-config", "enable=on,target=native", "-singlestep", "-d",
                    "exec,nochain", "-D", log, "-kernel", elf], input=b"bench\n",
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=1800)
    mark = mark_address(elf)
    counts = collections.Counter()
    marks = 0
    pc_re = re.compile(rb"\[[0-9a-f]+/([0-9a-f]+)/")
    with open(log, "rb") as f:
        for line in f:
            m = pc_re.search(line)
            if not m:
                continue
            pc = int(m.group(1), 16)
            if pc == mark:
                marks += 1
                if marks == 2:
                    break
                continue
            if marks == 1:
                counts[pc] += 1
    if not a.keep:
        os.remove(log)  # 1 GB: before the symbolizer runs
    if marks < 2:
        sys.exit(f"profile-step: found {marks} of the 2 marks (is `{a.row}` a bench row?)")
    addrs = sorted(counts)
    out = subprocess.run(["llvm-symbolizer", "--inlining", "--functions=short", "-e", elf],
                         input="".join(f"0x{x:x}\n" for x in addrs), capture_output=True,
                         text=True, check=True).stdout
    stacks = [
        [blk.split("\n")[i] for i in range(0, len(blk.split("\n")) - 1, 2)]
        for blk in out.strip("\n").split("\n\n")
    ]
    blocks, inner = collections.Counter(), collections.Counter()
    for ad, names in zip(addrs, stacks):
        c = counts[ad]
        short = [n.split("<")[0] for n in names]
        inner[short[0]] += c
        key = "outside the fused step: " + short[-1]
        for i, n in enumerate(short):
            if n == "update_impl" and i > 0:
                key = "robust law: " + short[i - 1]
                break
            if n == "step_fused":
                key = "fused step: " + (short[i - 1] if i > 0 else "(itself)")
                break
        blocks[key] += c
    total = sum(counts.values())
    print(f"{a.row}: {total / STEPS:.1f} instructions per step (bench loop and marks included)")
    print("\nby block (inlined into the fused step or the robust law's update):")
    for k, v in blocks.most_common():
        if v / STEPS >= 0.5:
            print(f"  {v / STEPS:7.1f}  {k}")
    print(f"\nby innermost function (top {a.top}):")
    for k, v in inner.most_common(a.top):
        print(f"  {v / STEPS:7.1f}  {k}")


def mark_address(elf):
    """Address of `bench::mark` (without the Thumb bit)."""
    nm = shutil.which("llvm-nm") or elf_tools.tool("llvm-nm")
    sym = subprocess.run([nm, "--defined-only", elf], capture_output=True, text=True,
                         check=True).stdout
    for line in sym.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[1] in "tT" and "bench4mark" in parts[2]:
            return int(parts[0], 16) & ~1
    sys.exit("profile-step: no bench::mark symbol in the ELF")


if __name__ == "__main__":
    main()
