"""The camera as the core consumes it, the pixel order of ray packets, and render windows."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .. import _core
from ..util import matrices

PACKET_RAYS = _core.PACKET_RAYS  # rays SplatCloud.trace / trace_surface take through the tree at once


def packet_order(width: int, height: int) -> np.ndarray:
    """Indices that put row-major pixel rays (Camera.rays) in 4x4 tiles, left to right and
    top to bottom (16 consecutive rays: one tile, one packet for trace() and
    trace_surface()); the inverse permutation is np.argsort of it."""
    if not (width > 0 and height > 0):
        raise ValueError(f"width and height must be positive, got {width}x{height}")
    side = math.isqrt(PACKET_RAYS)  # the core's blocks: 4x4
    rows, cols = np.divmod(np.arange(width * height), width)
    return np.lexsort((cols, rows, cols // side, rows // side))


def window_rect(window, width: int, height: int) -> tuple[int, int, int, int]:
    """(x0, y0, w, h) of a render window, checked before its buffers are allocated (a bad
    window such as (-1, -1, 1, 2**31 - 1) would ask numpy for 34 GB before the core
    refused it)."""
    x0, y0, w, h = (int(v) for v in (window if window is not None else (0, 0, width, height)))
    if not (width > 0 and height > 0 and 0 <= x0 and 0 <= y0 and w > 0 and h > 0 and x0 + w <= width
            and y0 + h <= height):
        raise ValueError(f"window ({x0}, {y0}, {w}, {h}) is not inside the {width}x{height} image")
    return x0, y0, w, h


@dataclass(frozen=True)
class Camera:
    """A pinhole or orthographic camera, as the core consumes it.

    local_from_ndc: 4x4 float64 mapping OpenGL normalised device coordinates (z = -1 on the
    near clipping plane, +1 on the far one) to points of the scene's local frame.
    position / forward: camera centre and unit view axis, for planar depth.
    """

    local_from_ndc: np.ndarray
    position: np.ndarray
    forward: np.ndarray

    @classmethod
    def from_view_projection(cls, projection, world_from_camera, origin=(0.0, 0.0, 0.0)) -> "Camera":
        """From a projection matrix (camera space to clip space, OpenGL convention, as
        Blender's `Object.calc_matrix_camera` returns) and the camera's rigid world matrix
        (looking down its local -Z); `origin` is the scene's local-frame origin."""
        proj = np.asarray(projection, dtype=np.float64).reshape(4, 4)
        w_c = np.asarray(world_from_camera, dtype=np.float64).reshape(4, 4)
        local_from_world = np.eye(4)
        local_from_world[:3, 3] = -np.asarray(origin, dtype=np.float64)
        local_from_ndc = local_from_world @ w_c @ matrices.inverse(proj)
        forward = -w_c[:3, 2] / np.linalg.norm(w_c[:3, 2])
        return cls(np.ascontiguousarray(local_from_ndc), w_c[:3, 3] - np.asarray(origin, np.float64), forward)

    @classmethod
    def look_at(cls, eye, target, up=(0.0, 0.0, 1.0), fov_y: float = 40.0, aspect: float = 4 / 3,
                near: float = 1e-3, far: float = 1e4, ortho_height: Optional[float] = None) -> "Camera":
        """A camera at `eye` looking at `target`. Perspective with vertical field of view
        `fov_y` (degrees), or orthographic when `ortho_height` (the view's height) is given."""
        eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
        if not all(np.isfinite(v).all() and v.shape == (3,) for v in (eye, target, up)):
            raise ValueError("eye, target and up must be three finite numbers each")
        if ortho_height is None and not 0.0 < fov_y < 180.0:
            raise ValueError(f"fov_y must be between 0 and 180 degrees (exclusive), got {fov_y!r}")
        if ortho_height is not None and not (np.isfinite(ortho_height) and ortho_height > 0):
            raise ValueError(f"ortho_height must be a positive number, got {ortho_height!r}")
        if not (np.isfinite(aspect) and aspect > 0):
            raise ValueError(f"aspect must be a positive number, got {aspect!r}")
        if not (0.0 < near < far < np.inf):
            raise ValueError(f"need 0 < near < far (finite), got near={near!r}, far={far!r}")
        fwd = target - eye
        if not np.linalg.norm(fwd) > 0:
            raise ValueError("eye and target are the same point")
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, up)
        if np.linalg.norm(right) < 1e-12:
            raise ValueError("up is parallel to the view direction")
        right /= np.linalg.norm(right)
        cam_up = np.cross(right, fwd)
        w_c = np.eye(4)
        w_c[:3, 0], w_c[:3, 1], w_c[:3, 2], w_c[:3, 3] = right, cam_up, -fwd, eye
        proj = np.zeros((4, 4))
        if ortho_height is None:
            f = 1.0 / np.tan(np.radians(fov_y) / 2)
            proj[0, 0], proj[1, 1] = f / aspect, f
            proj[2, 2], proj[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
            proj[3, 2] = -1.0
        else:
            proj[0, 0], proj[1, 1] = 2.0 / (ortho_height * aspect), 2.0 / ortho_height
            proj[2, 2], proj[2, 3] = -2.0 / (far - near), -(far + near) / (far - near)
            proj[3, 3] = 1.0
        return cls.from_view_projection(proj, w_c)

    def rays(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """Pixel-centre rays (origins on the near plane, unit directions), row-major from
        the top row: the same rays `SplatCloud.render` traces, for use with `SplatCloud.trace`."""
        j, i = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
        ndc = np.stack([2 * j / width - 1, 1 - 2 * i / height], axis=-1).reshape(-1, 2)
        def unproject(z):
            p = matrices.transform_rows(np.column_stack([ndc, np.full(len(ndc), z), np.ones(len(ndc))]), self.local_from_ndc)
            return p[:, :3] / p[:, 3:]
        a, b = unproject(-1.0), unproject(1.0)
        d = b - a
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return a.astype(np.float32), d.astype(np.float32)
