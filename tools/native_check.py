"""Reads what a built native module needs from the system it is loaded on, for each of the
three executable formats, without the target's tools (used by tests/release/test_portable.py).

    python -m tools.native_check FILE...     prints each file's facts

- ELF (Linux): the NEEDED libraries, the newest GLIBC_ symbol version required, the
  exported dynamic symbols, as binutils' readelf and objdump report them.
- PE (Windows): the machine, the DLLs imported (and which names from each), the exports;
  read from the headers here.
- Mach-O (macOS): the CPU, the dylibs loaded, the external symbols defined, and the
  undefined ones with the library each binds to (or flat lookup); read from the headers.
"""
from __future__ import annotations

import re
import struct
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class Facts:
    format: str                      # "ELF x86-64", "PE32+ x86-64", "Mach-O arm64", "Mach-O x86_64"
    libraries: list[str]             # NEEDED / imported DLLs / loaded dylibs
    exports: set[str]
    imports: dict[str, list[str]] = field(default_factory=dict)  # library -> names (PE, Mach-O)
    glibc: tuple[int, ...] = ()      # the newest GLIBC_x.y required (ELF)


def _version(v: str) -> tuple[int, ...]:
    return tuple(int(x) for x in v.split("."))


def elf(path: Path) -> Facts:
    dyn = subprocess.run(["readelf", "-d", "-W", str(path)], capture_output=True, text=True, check=True).stdout
    needed = re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", dyn)
    versions = subprocess.run(["readelf", "--version-info", "-W", str(path)], capture_output=True, text=True,
                              check=True).stdout
    dynsym = subprocess.run(["objdump", "-T", "-w", str(path)], capture_output=True, text=True, check=True).stdout
    glibc = {_version(v) for v in re.findall(r"GLIBC_(\d+(?:\.\d+)+)", versions + dynsym)}
    exports = set()
    for line in dynsym.splitlines():
        parts = line.split()
        if len(parts) >= 6 and "*UND*" not in line and re.match(r"^[0-9a-f]{8,}$", parts[0]) and " g " in line:
            exports.add(parts[-1])
    header = subprocess.run(["readelf", "-h", str(path)], capture_output=True, text=True, check=True).stdout
    machine = re.search(r"Machine:\s+(.*)", header).group(1).strip()
    return Facts(f"ELF {'x86-64' if 'X86-64' in machine else machine}", needed, exports, glibc=max(glibc, default=()))


def pe(data: bytes) -> Facts:
    (pe_offset,) = struct.unpack_from("<I", data, 0x3C)
    assert data[pe_offset:pe_offset + 4] == b"PE\0\0", "not a PE file"
    machine, n_sections, _, _, _, opt_size, _ = struct.unpack_from("<HHIIIHH", data, pe_offset + 4)
    opt = pe_offset + 24
    magic = struct.unpack_from("<H", data, opt)[0]
    kind = {0x20B: "PE32+", 0x10B: "PE32"}.get(magic, hex(magic))
    arch = {0x8664: "x86-64", 0xAA64: "arm64", 0x14C: "i386"}.get(machine, hex(machine))
    dirs = opt + (112 if magic == 0x20B else 96)
    sections = []
    for i in range(n_sections):
        s = opt + opt_size + 40 * i
        vsize, vaddr, rsize, raddr = struct.unpack_from("<IIII", data, s + 8)
        sections.append((vaddr, max(vsize, rsize), raddr))

    def off(rva: int) -> int:
        for vaddr, size, raddr in sections:
            if vaddr <= rva < vaddr + size:
                return rva - vaddr + raddr
        raise ValueError(f"RVA {rva:#x} in no section")

    def cstr(rva: int) -> str:
        o = off(rva)
        return data[o:data.index(b"\0", o)].decode()

    export_rva, _ = struct.unpack_from("<II", data, dirs)
    exports = set()
    if export_rva:
        # NumberOfNames at +24, AddressOfNames at +32 of the export directory.
        (n_names,) = struct.unpack_from("<I", data, off(export_rva) + 24)
        (names_rva,) = struct.unpack_from("<I", data, off(export_rva) + 32)
        for i in range(n_names):
            exports.add(cstr(struct.unpack_from("<I", data, off(names_rva) + 4 * i)[0]))
    import_rva, _ = struct.unpack_from("<II", data, dirs + 8)
    imports: dict[str, list[str]] = {}
    o = off(import_rva) if import_rva else None
    while o is not None:
        lookup, _, _, name_rva, thunks = struct.unpack_from("<IIIII", data, o)
        if name_rva == 0:
            break
        names, t = [], off(lookup or thunks)
        while True:
            (entry,) = struct.unpack_from("<Q", data, t)
            if entry == 0:
                break
            names.append(f"#{entry & 0xFFFF}" if entry >> 63 else cstr((entry & 0x7FFFFFFF) + 2))
            t += 8
        imports[cstr(name_rva)] = names
        o += 20
    return Facts(f"{kind} {arch}", list(imports), exports, imports)


MH_MAGIC_64, LC_SYMTAB, LC_DYSYMTAB = 0xFEEDFACF, 0x2, 0xB
LOAD_DYLIB = {0xC, 0x80000018, 0x8000001F, 0x80000023}  # load, weak, reexport, upward
CPU = {0x01000007: "x86_64", 0x0100000C: "arm64"}
DYNAMIC_LOOKUP = 0xFE


def macho(data: bytes) -> Facts:
    magic, cputype, _, _, ncmds, _, _, _ = struct.unpack_from("<IiiIIIII", data, 0)
    assert magic == MH_MAGIC_64, "not a 64-bit Mach-O file"
    libraries, symtab = [], None
    o = 32
    for _ in range(ncmds):
        cmd, size = struct.unpack_from("<II", data, o)
        if cmd in LOAD_DYLIB:
            (name_off,) = struct.unpack_from("<I", data, o + 8)
            libraries.append(data[o + name_off:data.index(b"\0", o + name_off)].decode())
        elif cmd == LC_SYMTAB:
            symtab = struct.unpack_from("<IIII", data, o + 8)
        o += size
    exports, imports = set(), {}
    if symtab:
        symoff, nsyms, stroff, _ = symtab
        for i in range(nsyms):
            strx, n_type, _, n_desc, _ = struct.unpack_from("<IBBHQ", data, symoff + 16 * i)
            name = data[stroff + strx:data.index(b"\0", stroff + strx)].decode()
            if n_type & 0xE0:  # a debugging (stab) entry
                continue
            external, kind = n_type & 0x01, n_type & 0x0E
            if external and kind == 0x0E:  # N_SECT: defined here
                exports.add(name[1:] if name.startswith("_") else name)
            elif external and kind == 0x00:  # N_UNDF: bound to a library ordinal
                ordinal = (n_desc >> 8) & 0xFF
                # -undefined dynamic_lookup: Zig's linker leaves ordinal 0 in the symbol
                # table (its bind opcodes say flat lookup; `llvm-objdump --macho --bind`
                # shows them as flat-namespace), ld64 writes DYNAMIC_LOOKUP_ORDINAL.
                lib = ("(flat lookup)" if ordinal in (0, DYNAMIC_LOOKUP) else
                       libraries[ordinal - 1] if 0 < ordinal <= len(libraries) else f"(ordinal {ordinal})")
                imports.setdefault(lib, []).append(name)
    return Facts(f"Mach-O {CPU.get(cputype, hex(cputype))}", libraries, exports, imports)


def facts(path: Path) -> Facts:
    data = Path(path).read_bytes()
    if data[:4] == b"\x7fELF":
        return elf(Path(path))
    if data[:2] == b"MZ":
        return pe(data)
    if data[:4] == struct.pack("<I", MH_MAGIC_64):
        return macho(data)
    raise ValueError(f"{path}: not an ELF, PE or 64-bit Mach-O file")


if __name__ == "__main__":
    for arg in sys.argv[1:]:
        f = facts(Path(arg))
        print(f"{arg}: {f.format}\n  libraries: {', '.join(f.libraries)}\n  exports: {', '.join(sorted(f.exports))}")
        if f.glibc:
            print(f"  newest GLIBC: {'.'.join(map(str, f.glibc))}")
        for lib, names in f.imports.items():
            print(f"  from {lib}: {len(names)} ({', '.join(sorted(names)[:8])}{', ...' if len(names) > 8 else ''})")
