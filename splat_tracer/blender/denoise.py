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

One OIDN device and its filters live across frames and viewport passes (creating them is most
of a small frame's denoising time); a filter is made again only when what it was made for
changes (size, guides, prefilter, quality), the device when the thread count does. One lock
serialises their use (final render and viewport threads); they are released when the add-on
is unregistered and at interpreter exit, before Blender unloads the library.
"""
from __future__ import annotations

import atexit
import ctypes
import os
import sys
import threading
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


class _Filter:
    """One "RT" filter with the images it reads and writes: OIDN keeps their addresses, so the
    frame's pixels are copied into them (the copy the float32 RGB conversion makes anyway)."""

    def __init__(self, lib, device, key, w: int, h: int, inputs, hdr: bool, clean_aux: bool, quality: str):
        self.key, self.lib = key, lib
        self.images = {name: np.zeros((h, w, 3), np.float32) for name in list(inputs) + ["output"]}
        self.handle = lib.oidnNewFilter(device, b"RT")
        if not self.handle:
            raise RuntimeError("OpenImageDenoise could not create its filter")
        for name, a in self.images.items():
            lib.oidnSetSharedFilterImage(self.handle, name.encode(), a.ctypes.data, _FORMAT_FLOAT3, w, h, 0, 0, 0)
        if hdr:
            lib.oidnSetFilterBool(self.handle, b"hdr", True)
        if clean_aux:
            lib.oidnSetFilterBool(self.handle, b"cleanAux", True)
        lib.oidnSetFilterInt(self.handle, b"quality", QUALITY.get(quality, QUALITY["HIGH"]))
        lib.oidnCommitFilter(self.handle)

    def release(self):
        if self.handle:
            self.lib.oidnReleaseFilter(self.handle)
            self.handle = None


class _Device:
    """The CPU device for one thread count, with its filters by role ("albedo", "normal" for
    Accurate's prefilter passes, "color" for the main one)."""

    def __init__(self, lib, threads: int):
        self.lib, self.threads, self.filters = lib, threads, {}
        self.handle = lib.oidnNewDevice(_DEVICE_CPU)
        if not self.handle:
            raise RuntimeError("OpenImageDenoise could not create its CPU device")
        if threads > 0:
            lib.oidnSetDeviceInt(self.handle, b"numThreads", int(threads))
        lib.oidnCommitDevice(self.handle)
        self.check()

    def check(self):
        message = ctypes.c_char_p()
        if self.lib.oidnGetDeviceError(self.handle, ctypes.byref(message)):
            raise RuntimeError(f"OpenImageDenoise: {(message.value or b'error').decode(errors='replace')}")

    def filter(self, role: str, key, *args) -> _Filter:
        f = self.filters.get(role)
        if f is None or f.key != key:
            if f is not None:
                f.release()
                del self.filters[role]
            f = self.filters[role] = _Filter(self.lib, self.handle, key, *args)
        return f

    def release(self):
        for f in self.filters.values():
            f.release()
        self.filters.clear()
        if self.handle:
            self.lib.oidnReleaseDevice(self.handle)
            self.handle = None


_lock = threading.Lock()
_device: Optional[_Device] = None
# Devices and filters created so far: tests see the device reused and the filters remade.
CREATED = {"devices": 0, "filters": 0}


def denoise(color: np.ndarray, albedo: Optional[np.ndarray] = None, normal: Optional[np.ndarray] = None,
            prefilter: str = "ACCURATE", quality: str = "HIGH", threads: int = 0) -> np.ndarray:
    """The (h, w, 3) colour denoised by OIDN's "RT" filter, guided by the (h, w, 3) albedo and
    (with it) normal when given. Raises RuntimeError with OIDN's message when it fails."""
    global _device
    lib = library()
    if lib is None:
        raise RuntimeError("Blender's OpenImageDenoise library was not found")
    h, w = color.shape[:2]
    guides = {}
    if albedo is not None:
        guides["albedo"] = albedo
        if normal is not None:
            guides["normal"] = normal
    threads = max(0, int(threads))
    with _lock:
        try:
            if _device is not None and _device.threads != threads:
                _device.release()
                _device = None
            if _device is None:
                _device = _Device(lib, threads)
                CREATED["devices"] += 1

            def run(role: str, inputs: dict, hdr: bool, clean_aux: bool) -> np.ndarray:
                key = (w, h, tuple(inputs), hdr, clean_aux, quality)
                before = _device.filters.get(role)
                f = _device.filter(role, key, w, h, tuple(inputs), hdr, clean_aux, quality)
                CREATED["filters"] += f is not before
                for name, a in inputs.items():
                    np.copyto(f.images[name], a[..., :3], casting="unsafe")
                lib.oidnExecuteFilter(f.handle)
                _device.check()
                return f.images["output"]

            if prefilter == "ACCURATE":
                # Cycles' Accurate: each guide denoised on its own first (a filter whose only
                # input is the albedo or the normal image denoises it; normals are not HDR).
                for name in list(guides):
                    guides[name] = run(name, {name: guides[name]}, False, False)
            return run("color", {"color": color, **guides}, True, prefilter != "FAST" and bool(guides)).copy()
        except RuntimeError:
            # A device in error is not kept: the next frame starts from a fresh one.
            _release_locked()
            raise


def _release_locked():
    global _device
    if _device is not None:
        _device.release()
        _device = None


# Seconds release() waits for a denoise in flight (another thread's) before leaving the device
# alive: a frame at a few megapixels takes seconds on a loaded machine; leaking at exit is
# harmless, waiting forever is not.
_RELEASE_WAIT = 30.0


@atexit.register
def release() -> None:
    """Release the kept device and filters (add-on unregister, interpreter exit). The
    viewport's own atexit hook, registered after this one (viewport.py imports this module),
    runs first and stops its sessions."""
    if _lock.acquire(timeout=_RELEASE_WAIT):
        try:
            _release_locked()
        finally:
            _lock.release()
