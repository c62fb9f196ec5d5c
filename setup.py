"""Builds the native core, splat_tracer/_core.abi3.so, in place.

    python setup.py build_ext --inplace      (what `make build` runs)

One binary for every Blender from 4.2 to 5.2 (blender_manifest.toml's range): it is compiled against the CPython limited
API of Python 3.11 (abi3), which Python 3.11 to 3.13 all load. This file is only a build
script; the project is installed as a Blender extension, not as a Python package.

    SPLAT_SANITIZE=1 python setup.py build_ext --build-lib DIR   (what `make test-sanitize` runs)

builds a debugging variant instead: AddressSanitizer + UndefinedBehaviorSanitizer, -O1 with
debug info, and the C++ runtime linked dynamically (the sanitizer runtimes replace its
allocator). It is never shipped; the Makefile builds it into build/sanitize/, away from the
normal in-place binary.
"""
import os
from pathlib import Path

from setuptools import Extension, setup

NATIVE = Path("splat_tracer") / "native"

core = Extension(
    "splat_tracer._core",
    sources=sorted(str(p) for p in NATIVE.rglob("*.cpp")),
    depends=sorted(str(p) for p in NATIVE.rglob("*.h")),
    # Includes are written from the native root ("base/vec3.h"), one folder per idea.
    include_dirs=[str(NATIVE)],
    language="c++",
    define_macros=[("Py_LIMITED_API", "0x030B0000")],
    py_limited_api=True,
    # The binary ships inside the extension zip: portable x86-64 code (no -march=native),
    # no debug info, and the C++ runtime linked in, so that it does not depend on the
    # libstdc++ of whatever system Blender runs on.
    extra_compile_args=["-std=c++17", "-O3", "-g0", "-fvisibility=hidden", "-Wall", "-Wextra", "-pthread"],
    extra_link_args=["-pthread", "-static-libstdc++", "-static-libgcc", "-s"],
)
if os.environ.get("SPLAT_SANITIZE") == "1":
    # Any undefined behaviour aborts (no recovery), so that a test cannot pass over it.
    # float-cast-overflow (a float out of an integer's range converted to it) is UB that
    # GCC's -fsanitize=undefined leaves out; it is asked for by name.
    SANITIZE = ["-fsanitize=address,undefined,float-cast-overflow",
                "-fno-sanitize-recover=undefined,float-cast-overflow", "-fno-omit-frame-pointer"]
    # Python's own CFLAGS come first: -fwrapv would define signed overflow away (UBSan would
    # not check it) and -DNDEBUG would turn asserts off; both are undone here.
    core.extra_compile_args = ["-std=c++17", "-O1", "-g", "-fvisibility=hidden", "-Wall", "-Wextra", "-pthread",
                               "-fno-wrapv", "-UNDEBUG", *SANITIZE]
    core.extra_link_args = ["-pthread", *SANITIZE]


setup(
    name="splat_tracer_core",
    version="0.1.0",
    ext_modules=[core],
    options={"bdist_wheel": {"py_limited_api": "cp311"}},
)
