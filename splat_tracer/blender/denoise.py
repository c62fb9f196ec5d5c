"""Denoising with OpenImageDenoise as Blender ships it: the OIDN library Blender itself links
(Cycles' and the compositor's denoiser), called through ctypes on the CPU. No new dependency:
the library is already loaded in Blender's process, so finding it is asking the dynamic loader
for it by name, or loading it from Blender's own library folder.

Its settings are Cycles' (scene.cycles: denoising_input_passes, denoising_prefilter,
denoising_quality; export/settings.py reads them), and it is used as Cycles' OIDN denoiser
uses it (intern/cycles/integrator/denoiser_oidn.cpp): the "RT" filter on HDR colour, with the
albedo and normal guides; prefilter Accurate denoises the guides first (each its own "RT"
filter) and tells the main filter they are clean, Fast gives them noisy, None gives them as
clean without prefiltering them.
"""
from __future__ import annotations

import ctypes
import os
import sys
from typing import Optional

import numpy as np

# OIDN's C API constants (OpenImageDenoise/oidn.h, 2.x): the CPU device, the float3 format,
# the filter qualities Cycles' Quality setting maps to.
_DEVICE_CPU = 1
_FORMAT_FLOAT3 = 3
QUALITY = {"HIGH": 6, "BALANCED": 5, "FAST": 4}

_LIBRARY = None


def _candidates() -> list:
    """Where Blender keeps OIDN: loaded already by name (Blender links it), else its library
    folder (the bpy module's lib/, the app's lib/ or blender.shared/)."""
    if sys.platform == "win32":
        names = ["OpenImageDenoise.dll"]
    elif sys.platform == "darwin":
        names = ["libOpenImageDenoise.2.dylib", "libOpenImageDenoise.dylib"]
    else:
        names = ["libOpenImageDenoise.so.2", "libOpenImageDenoise.so"]
    folders = []
    try:
        import bpy

        here = os.path.dirname(os.path.abspath(getattr(bpy, "__file__", "") or ""))
        binary = os.path.dirname(bpy.app.binary_path or "")
        folders = [os.path.join(here, "lib"), os.path.join(binary, "lib"), os.path.join(binary, "blender.shared"),
                   os.path.join(binary, "..", "Resources", "lib")]
    except Exception:  # noqa: BLE001 - no bpy: only the loader's search
        pass
    return names + [os.path.join(f, n) for f in folders for n in names]


def library():
    """The OIDN library with its functions' signatures, or None when Blender has none."""
    global _LIBRARY
    if _LIBRARY is not None:
        return _LIBRARY or None
    for candidate in _candidates():
        try:
            lib = ctypes.CDLL(candidate)
            break
        except OSError:
            continue
    else:
        _LIBRARY = False
        return None
    p, s, i, b, size = ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_bool, ctypes.c_size_t
    for name, res, args in (
            ("oidnNewDevice", p, [i]), ("oidnCommitDevice", None, [p]), ("oidnReleaseDevice", None, [p]),
            ("oidnSetDeviceInt", None, [p, s, i]), ("oidnGetDeviceError", i, [p, ctypes.POINTER(s)]),
            ("oidnNewFilter", p, [p, s]), ("oidnReleaseFilter", None, [p]),
            ("oidnSetSharedFilterImage", None, [p, s, p, i, size, size, size, size, size]),
            ("oidnSetFilterBool", None, [p, s, b]), ("oidnSetFilterInt", None, [p, s, i]),
            ("oidnCommitFilter", None, [p]), ("oidnExecuteFilter", None, [p])):
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = res, args
    _LIBRARY = lib
    return lib


def available() -> bool:
    return library() is not None


def denoise(color: np.ndarray, albedo: Optional[np.ndarray] = None, normal: Optional[np.ndarray] = None,
            prefilter: str = "ACCURATE", quality: str = "HIGH", threads: int = 0) -> np.ndarray:
    """The (h, w, 3) colour denoised by OIDN's "RT" filter, guided by the (h, w, 3) albedo and
    (with it) normal when given. Raises RuntimeError with OIDN's message when it fails."""
    lib = library()
    if lib is None:
        raise RuntimeError("Blender's OpenImageDenoise library was not found")
    h, w = color.shape[:2]
    image = lambda a: np.ascontiguousarray(a[..., :3], dtype=np.float32)
    color, out = image(color), np.zeros((h, w, 3), np.float32)
    guides = {}
    if albedo is not None:
        guides["albedo"] = image(albedo)
        if normal is not None:
            guides["normal"] = image(normal)
    device = lib.oidnNewDevice(_DEVICE_CPU)
    if not device:
        raise RuntimeError("OpenImageDenoise could not create its CPU device")
    filters = []

    def run(inputs: dict, output: np.ndarray, clean_aux: bool, hdr: bool):
        f = lib.oidnNewFilter(device, b"RT")
        filters.append(f)
        for name, a in list(inputs.items()) + [("output", output)]:
            lib.oidnSetSharedFilterImage(f, name.encode(), a.ctypes.data, _FORMAT_FLOAT3, w, h, 0, 0, 0)
        if hdr:
            lib.oidnSetFilterBool(f, b"hdr", True)
        if clean_aux:
            lib.oidnSetFilterBool(f, b"cleanAux", True)
        lib.oidnSetFilterInt(f, b"quality", QUALITY.get(quality, QUALITY["HIGH"]))
        lib.oidnCommitFilter(f)
        lib.oidnExecuteFilter(f)
        message = ctypes.c_char_p()
        if lib.oidnGetDeviceError(device, ctypes.byref(message)):
            raise RuntimeError(f"OpenImageDenoise: {(message.value or b'error').decode(errors='replace')}")

    try:
        if threads > 0:
            lib.oidnSetDeviceInt(device, b"numThreads", int(threads))
        lib.oidnCommitDevice(device)
        if prefilter == "ACCURATE":
            # Cycles' Accurate: each guide denoised on its own first (an albedo or a normal
            # image is the filter's colour input; normals are not HDR).
            for name, guide in guides.items():
                clean = np.empty_like(guide)
                run({name: guide}, clean, False, False)
                guides[name] = clean
        run({"color": color, **guides}, out, prefilter != "FAST" and bool(guides), True)
    finally:
        for f in filters:
            lib.oidnReleaseFilter(f)
        lib.oidnReleaseDevice(device)
    return out
