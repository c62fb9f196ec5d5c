"""Cryptomatte (Psyop's open standard, as Cycles writes it and Blender's compositor reads it):
the names' ids, the passes' layout and the manifest.

A name (an object's, a material's, an asset's) becomes an id by MurmurHash3_32 (seed 0) of
its UTF-8 bytes, seen as a float32 ("uint32_to_float32"): the hash's bits are the float's,
except that an exponent of all zeros or all ones (a denormal, an infinity or a NaN) gets its
lowest exponent bit flipped, so every id is a normal finite number (and none is 0, which
marks an empty slot). The manifest maps each name to its hash in 8 hex digits (before the
fix). The core (native/shade/cryptomatte.h) accumulates, per pixel, each id's share of the
camera samples and sorts by it.
"""
from __future__ import annotations

import json
import struct
from typing import Iterable

# The view layer's kinds, in the core's order: Blender's pass prefix for each. Each kind is
# written as <prefix>00, <prefix>01, ...: RGBA layers of two (id, coverage) pairs.
KINDS = ("CryptoObject", "CryptoMaterial", "CryptoAsset")
# Cycles' name of the shader that surfaces without a material get (its default surface).
DEFAULT_MATERIAL = "default_surface"


def murmur3_32(data: bytes, seed: int = 0) -> int:
    """MurmurHash3's 32-bit x86 variant (Appleby), the hash the standard names."""
    c1, c2, mask = 0xCC9E2D51, 0x1B873593, 0xFFFFFFFF
    h = seed & mask
    rotl = lambda x, r: ((x << r) | (x >> (32 - r))) & mask
    end = len(data) & ~3
    for i in range(0, end, 4):
        k = int.from_bytes(data[i:i + 4], "little")
        k = rotl((k * c1) & mask, 15) * c2 & mask
        h = (rotl(h ^ k, 13) * 5 + 0xE6546B64) & mask
    tail = data[end:]
    if tail:
        k = int.from_bytes(tail, "little")
        h ^= rotl((k * c1) & mask, 15) * c2 & mask
    h ^= len(data)
    h = ((h ^ (h >> 16)) * 0x85EBCA6B) & mask
    h = ((h ^ (h >> 13)) * 0xC2B2AE35) & mask
    return h ^ (h >> 16)


def name_hash(name: str) -> int:
    return murmur3_32(name.encode("utf-8"))


def hash_to_float(h: int) -> float:
    """uint32_to_float32: the hash's bits as a float32, an exponent of 0 or 255 made normal."""
    exponent = (h >> 23) & 0xFF
    if exponent in (0, 0xFF):
        h ^= 1 << 23
    return struct.unpack("<f", struct.pack("<I", h))[0]


def name_id(name: str) -> float:
    """The id a pixel stores for `name`."""
    return hash_to_float(name_hash(name))


def slots_of(levels: int) -> int:
    """The (id, coverage) pairs a pixel keeps for Blender's Levels (view_layer.
    pass_cryptomatte_depth): two per RGBA layer, as many layers as hold `levels` pairs -- as
    Cycles rounds (an odd level count gets its last layer whole)."""
    levels = max(1, min(int(levels), 16))  # Blender's range is 2..16
    return 2 * ((levels + 1) // 2)


def layers(kind: str, pixels) -> dict:
    """The RGBA layers of one kind, by Blender's pass name: `pixels` is the core's (h, w, 2
    slots) buffer, cut into <kind>00, <kind>01, ... of 4 channels each."""
    return {f"{kind}{i:02d}": pixels[:, :, 4 * i:4 * i + 4] for i in range(pixels.shape[2] // 4)}


def manifest(names: Iterable[str]) -> str:
    """The manifest: a JSON object from each name to its hash in 8 hex digits."""
    return json.dumps({n: f"{name_hash(n):08x}" for n in dict.fromkeys(names)}, separators=(",", ":"), ensure_ascii=False)


def metadata(layer_name: str, names: Iterable[str]) -> dict:
    """The render result's metadata for one kind of one view layer (`layer_name`, e.g.
    'ViewLayer.CryptoObject'), as Cycles writes it: cryptomatte/<key>/{name, hash,
    conversion, manifest}, the key being the first 7 hex digits of the layer name's hash."""
    prefix = f"cryptomatte/{name_hash(layer_name):08x}"[:-1] + "/"  # 7 of the 8 digits
    return {prefix + "name": layer_name, prefix + "hash": "MurmurHash3_32", prefix + "conversion": "uint32_to_float32",
            prefix + "manifest": manifest(names)}
