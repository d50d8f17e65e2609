"""Helpers the firmware ELF checks share (.ci/firmware-code.py, .ci/firmware-safety.py):
the LLVM tools of the active toolchain and linker thunk names."""
import os
import re
import subprocess


def thunk_target(name):
    """A linker range-extension thunk (`__Thumbv7ABSLongThunk_<f>`: a call between the H743's
    ITCM at 0 and its flash at 0x0800_0000) stands for a call of `f`."""
    m = re.match(r"^__\w*LongThunk_(.+)$", name)
    return m.group(1) if m else name


def tool(name):
    """Path of an LLVM tool (`llvm-objdump`, ...) of the rustc in use (llvm-tools component)."""
    sysroot = subprocess.check_output(["rustc", "--print", "sysroot"], text=True).strip()
    host = next(l.split(": ")[1] for l in subprocess.check_output(["rustc", "-vV"], text=True).splitlines() if l.startswith("host"))
    return os.path.join(sysroot, "lib", "rustlib", host, "bin", name)
