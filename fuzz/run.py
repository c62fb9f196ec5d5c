"""Runs every fuzz harness for a share of a time budget (what `make fuzz` calls).

    python -m fuzz.run --seconds 120 [--sanitized build/sanitize/tree]

Harnesses (one per entry point, each documented in its file): fuzz_ply.py (the PLY reader
and the import preparation behind it), fuzz_prepare.py (the import preparation on fuzzed
arrays), fuzz_core.py (the native Scene, Mesh and RenderScene entry points), and one per
other reader, each through the importer's steps (fuzz/reading.py): fuzz_las.py (LAS/LAZ),
fuzz_e57.py (E57), fuzz_text.py (XYZ/PTS/TXT/CSV), fuzz_pcd.py (PCD). Each runs for
seconds / 7 with its seed
corpus fuzz/corpus/<name>/ (read only: what the fuzzer learns goes to
build/fuzz/corpus/<name>/, kept between runs; fuzz/make_corpus.py writes the readers'
seeds). An input that runs longer than its harness's timeout (TIMEOUTS) is a finding: a
reader given a file of a few KB that takes 10 s is looping or allocating from a corrupt
count. With --sanitized, the core
harness's whole corpus (seeds and learnt) is then replayed, once each, against the ASan +
UBSan build in that tree: under the preloaded ASan runtime atheris gets no coverage
signal, so the coverage-guided search runs on the normal build and the sanitizers judge
what it found. A finding stops its harness; its input is written to build/fuzz/<name>-crash-*
(replay: python -m fuzz.fuzz_<name> FILE) and this script exits 1. It prints the executions
of each harness.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
HARNESSES = ("ply", "prepare", "core", "las", "e57", "text", "pcd")
# Seconds one input may take (libFuzzer's -timeout). The readers' seeds import in well under
# 0.1 s each; the core's inputs render, so they get more.
TIMEOUTS = {"ply": 60, "prepare": 60, "core": 60, "las": 10, "e57": 10, "text": 10, "pcd": 10}
# Longest input (libFuzzer's -max_len; its default is the longest seed): E57 mutations
# rewrite the XML, which may grow the file by a page or two.
MAX_LEN = {"e57": 16384}


def sanitizer_env() -> dict:
    libs = [subprocess.check_output(["gcc", f"-print-file-name={lib}"], text=True).strip()
            for lib in ("libasan.so", "libstdc++.so")]
    return {**os.environ, "LD_PRELOAD": " ".join(libs), "ASAN_OPTIONS": "detect_leaks=0",
            "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1"}


def run(name: str, harness_root: Path, args: list[str], env=None, label: str = "") -> tuple[bool, int]:
    out = ROOT / "build" / "fuzz"
    log = out / f"{name}{label}.log"
    cmd = [sys.executable, "-m", f"fuzz.fuzz_{name}", *args,
           f"-artifact_prefix={out}/{name}-", "-rss_limit_mb=8192", f"-timeout={TIMEOUTS[name]}",
           *([f"-max_len={MAX_LEN[name]}"] if name in MAX_LEN else []), "-print_final_stats=1"]
    with open(log, "w") as f:  # run from harness_root: its splat_tracer is the one fuzzed
        code = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, env=env, cwd=harness_root).returncode
    text = log.read_text(errors="replace")
    runs = re.findall(r"stat::number_of_executed_units:\s*(\d+)", text)
    executions = int(runs[-1]) if runs else 0
    if code != 0:
        print(f"fuzz_{name}{label}: FINDING (exit {code}); log {log}\n" + "\n".join(text.splitlines()[-60:]))
    return code == 0, executions


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=int, default=120, help="total budget, split evenly (default 120)")
    ap.add_argument("--sanitized", type=Path, help="a tree with the ASan + UBSan core (make sanitize-tree)")
    opts = ap.parse_args()
    each = max(1, opts.seconds // len(HARNESSES))
    ok = True
    for name in HARNESSES:
        learnt = ROOT / "build" / "fuzz" / "corpus" / name
        learnt.mkdir(parents=True, exist_ok=True)
        seeds = HERE / "corpus" / name
        good, n = run(name, ROOT, [str(learnt), str(seeds), f"-max_total_time={each}"])
        print(f"fuzz_{name}: {n:,} executions in {each} s, {'no finding' if good else 'FINDING'}")
        ok &= good
        if good and name == "core" and opts.sanitized:
            good, n = run(name, opts.sanitized.resolve(), [str(learnt), str(seeds), "-runs=0"], sanitizer_env(),
                          label="-sanitized")
            print(f"fuzz_{name} corpus under ASan + UBSan: {n:,} inputs replayed, "
                  f"{'no finding' if good else 'FINDING'}")
            ok &= good
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
