"""The camera as the core consumes it, the pixel order of ray packets, and render windows."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .. import _core

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


def _numbers(values, name: str, count: int) -> tuple:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {count} numbers, got {values!r}") from None
    if len(out) != count or not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} must be {count} finite numbers, got {values!r}")
    return out


# Cycles clamps the f-stop and the focus distance from below so that neither divides by 0
# (blender/camera.cpp: max(fstop, 1e-5); scene/camera.cpp: max(focaldistance, 1e-5)).
MIN_FSTOP = 1e-5
MIN_FOCUS_DISTANCE = 1e-5


@dataclass(frozen=True)
class Lens:
    """A thin lens (depth of field), as Cycles models Blender's camera: rays leave a point
    of the aperture and meet the pinhole ray of their pixel position on the plane in focus.

    radius: the aperture's radius in camera-space units (from_fstop gives Blender's).
    focus_distance: the plane in focus, along the view axis from the camera (an
    orthographic camera's too). blades: 0 (or 1, 2) for a disc, 3 or more for a regular
    polygon whose corners lie on the circle at angles rotation + (2k + 1) pi / blades from
    the camera's x axis (Cycles' regular_polygon_sample). rotation: radians. ratio: the
    anamorphic ratio: the aperture's x extent is divided by it.
    """

    radius: float
    focus_distance: float
    blades: int = 0
    rotation: float = 0.0
    ratio: float = 1.0

    def __post_init__(self):
        radius, focus, rotation, ratio = _numbers((self.radius, self.focus_distance, self.rotation, self.ratio),
                                                  "radius, focus_distance, rotation and ratio", 4)
        try:
            blades = int(self.blades)
        except (TypeError, ValueError):
            raise ValueError(f"blades must be an integer, got {self.blades!r}") from None
        if not (radius >= 0 and focus > 0 and ratio > 0 and 0 <= blades <= 65536):
            raise ValueError(f"need radius >= 0, focus_distance > 0, ratio > 0 and 0 <= blades <= 65536, got "
                             f"{self.radius!r}, {self.focus_distance!r}, {self.ratio!r}, {self.blades!r}")
        object.__setattr__(self, "radius", radius)
        object.__setattr__(self, "focus_distance", focus)
        object.__setattr__(self, "blades", blades if blades >= 3 else 0)  # fewer than 3: a disc (Cycles)
        object.__setattr__(self, "rotation", rotation)
        object.__setattr__(self, "ratio", ratio)

    @classmethod
    def from_fstop(cls, fstop: float, focal_length: float, focus_distance: float, blades: int = 0,
                   rotation: float = 0.0, ratio: float = 1.0, orthographic: bool = False) -> "Lens":
        """Blender's Depth of Field settings as Cycles reads them (blender/camera.cpp): the
        aperture radius is the focal length (mm, read as 1e-3 scene units whatever the
        unit scale, as Cycles does) over twice the f-stop; an orthographic camera's is
        1 / (2 f-stop) scene units. The sensor and its fit play no part. Both the f-stop
        and the focus distance are clamped to 1e-5 from below, as Cycles clamps them."""
        stop = max(float(fstop), MIN_FSTOP)
        radius = 1.0 / (2.0 * stop) if orthographic else (float(focal_length) * 1e-3) / (2.0 * stop)
        return cls(radius, max(float(focus_distance), MIN_FOCUS_DISTANCE), blades, rotation, ratio)

    def native(self) -> tuple:
        """The `lens` argument the core's scene render takes."""
        return (self.radius, self.focus_distance, self.blades, self.rotation, self.ratio)


# The core's projections (scene/camera.h Camera::Projection), in its order: "PLANAR" is a
# pinhole or an orthographic camera; the others are Cycles' panorama types of those names.
PROJECTIONS = ("PLANAR", "EQUIRECTANGULAR", "FISHEYE_EQUIDISTANT", "FISHEYE_EQUISOLID", "MIRRORBALL")
_PANORAMA_PARAMETERS = {"EQUIRECTANGULAR": 4, "FISHEYE_EQUIDISTANT": 1, "FISHEYE_EQUISOLID": 4, "MIRRORBALL": 0}


@dataclass(frozen=True)
class Panorama:
    """A panoramic projection as Cycles has it (kernel/camera/projection.h): which of
    PROJECTIONS[1:] and its parameters, angles in radians, lengths in mm:
    EQUIRECTANGULAR (longitude min, max, latitude min, max): the image's columns run the
    longitude from min to max (positive to the camera's right), its rows the latitude
    (positive up, max at the top); FISHEYE_EQUIDISTANT (field of view): the image's
    unit square holds the circle, the angle off the view axis is r fov / 2;
    FISHEYE_EQUISOLID (lens, field of view, sensor width, sensor height): r on the sensor
    is 2 lens sin(angle / 2), cut at the field of view (the sensor as Cycles fits it to
    the image: Panorama.equisolid_sensor); MIRRORBALL (): a mirror ball filling the image
    square, its centre looking down the view axis. Pixels outside a fisheye's circle or
    the ball see nothing (black, alpha 0, as in Cycles)."""

    kind: str
    parameters: tuple = ()

    def __post_init__(self):
        if self.kind not in _PANORAMA_PARAMETERS:
            raise ValueError(f"panorama kind must be one of {', '.join(_PANORAMA_PARAMETERS)}, got {self.kind!r}")
        count = _PANORAMA_PARAMETERS[self.kind]
        values = _numbers(self.parameters, f"{self.kind} parameters", count) if count else ()
        if self.kind == "FISHEYE_EQUIDISTANT" and not values[0] > 0:
            raise ValueError(f"a fisheye's field of view must be > 0, got {values[0]!r}")
        if self.kind == "FISHEYE_EQUISOLID" and not all(v > 0 for v in values):
            raise ValueError(f"an equisolid fisheye's lens, field of view and sensor must be > 0, got {values!r}")
        object.__setattr__(self, "parameters", values)

    @staticmethod
    def equisolid_sensor(sensor_width: float, sensor_height: float, sensor_fit: str, width: float,
                         height: float) -> tuple:
        """The sensor (width, height) an equisolid fisheye maps the image to, as Cycles'
        blender/camera.cpp fits it: the fitted side's sensor size (AUTO: the width, along
        the image's longer side), the other side in the image's proportion. width and
        height: the image's size times the pixel aspect."""
        horizontal = width > height if sensor_fit == "AUTO" else sensor_fit == "HORIZONTAL"
        size = sensor_height if sensor_fit == "VERTICAL" else sensor_width
        return (size, size * height / width) if horizontal else (size * width / height, size)

    def native(self) -> tuple:
        """The projection's index in PROJECTIONS and 5 parameters (unused ones 0)."""
        return (float(PROJECTIONS.index(self.kind)), *self.parameters, *(0.0,) * (5 - len(self.parameters)))


@dataclass(frozen=True)
class Camera:
    """A pinhole or orthographic camera, as the core consumes it: its parameters in double
    precision. The core builds each ray from them; it never inverts a projection matrix,
    which for clipping ranges of about 1e8 and more (0.001 to 1e5 m) unprojects the far
    plane to w = 0 in float32 (Blender's) and, at the ranges Blender allows, in double too.

    local_from_camera: 4x4 float64 affine map from camera space (looking down -Z, +Y up) to
    the scene's local frame. frustum: (left, right, bottom, top) of the image on the plane
    at unit distance in front of a pinhole camera, or on the view plane of an orthographic
    one (scene units). clip: (start, end) distances along the view axis between which rays
    run (start may be negative for an orthographic camera). lens: a thin lens (depth of
    field; its units are camera space's), or None for a pinhole. position / forward: camera
    centre and unit view axis, for planar depth. panorama: a panoramic projection, or None;
    its frustum is the image's rectangle in Cycles' panorama (u, v) coordinates ((0, 1, 0,
    1), moved by the lens shift), its rays leave the camera's centre (or its lens) and are
    clipped at clip start and end along themselves, and its Depth pass is the distance from
    the camera (Cycles' camera_z_depth). motion: motion blur -- local_from_camera at S >= 2
    evenly spaced times over the shutter (S 4x4 matrices, the first at its opening), or None
    for a camera that does not move (local_from_camera is the frame's own either way).
    """

    local_from_camera: np.ndarray
    frustum: tuple
    clip: tuple
    orthographic: bool = False
    lens: Optional[Lens] = None
    panorama: Optional[Panorama] = None
    motion: Optional[np.ndarray] = None

    def __post_init__(self):
        m = np.array(self.local_from_camera, dtype=np.float64)
        if m.shape != (4, 4) or not np.isfinite(m).all() or tuple(m[3]) != (0.0, 0.0, 0.0, 1.0):
            raise ValueError("local_from_camera must be a finite affine 4x4 matrix (last row 0 0 0 1)")
        if not np.linalg.norm(m[:3, 2]) > 0:
            raise ValueError("local_from_camera has no view axis (its -Z column is zero)")
        left, right, bottom, top = _numbers(self.frustum, "frustum", 4)
        if not (left < right and bottom < top):
            raise ValueError(f"frustum needs left < right and bottom < top, got {self.frustum!r}")
        start, end = _numbers(self.clip, "clip", 2)
        if not (start < end and (self.orthographic or start > 0)):
            raise ValueError(f"need clip start < clip end (and clip start > 0 for a perspective camera), "
                             f"got {self.clip!r}")
        object.__setattr__(self, "local_from_camera", np.ascontiguousarray(m))
        object.__setattr__(self, "frustum", (left, right, bottom, top))
        object.__setattr__(self, "clip", (start, end))
        object.__setattr__(self, "orthographic", bool(self.orthographic))
        if self.lens is not None and not isinstance(self.lens, Lens):
            raise TypeError(f"lens must be a Lens or None, got {type(self.lens).__name__}")
        if self.lens is not None and self.lens.radius == 0:
            object.__setattr__(self, "lens", None)  # a closed aperture is a pinhole
        if self.panorama is not None and not isinstance(self.panorama, Panorama):
            raise TypeError(f"panorama must be a Panorama or None, got {type(self.panorama).__name__}")
        if self.panorama is not None and self.orthographic:
            raise ValueError("a camera is either orthographic or panoramic")
        if self.motion is not None:
            steps = np.array(self.motion, dtype=np.float64)
            if (steps.ndim != 3 or len(steps) < 2 or steps.shape[1:] != (4, 4) or not np.isfinite(steps).all()
                    or (steps[:, 3] != (0.0, 0.0, 0.0, 1.0)).any()):
                raise ValueError("camera motion must be at least two finite affine 4x4 matrices")
            object.__setattr__(self, "motion", np.ascontiguousarray(steps))

    @property
    def position(self) -> np.ndarray:
        return self.local_from_camera[:3, 3].copy()

    @property
    def forward(self) -> np.ndarray:
        axis = self.local_from_camera[:3, 2]
        return -axis / np.linalg.norm(axis)

    def native(self) -> tuple:
        """The arguments the core's render calls take for the camera (its lens apart:
        `lens.native()`)."""
        projection = self.panorama.native() if self.panorama is not None else (0.0,) * 6
        return (self.local_from_camera, np.array([*self.frustum, *self.clip, *projection], np.float64),
                self.orthographic)

    def with_lens(self, lens: Optional[Lens]) -> "Camera":
        """This camera with another lens (None: a pinhole)."""
        return Camera(self.local_from_camera, self.frustum, self.clip, self.orthographic, lens, self.panorama,
                      self.motion)

    @classmethod
    def from_frustum(cls, world_from_camera, frustum, clip, orthographic: bool = False,
                     origin=(0.0, 0.0, 0.0), lens: Optional[Lens] = None,
                     panorama: Optional[Panorama] = None, motion=None) -> "Camera":
        """From the camera's world matrix (looking down its local -Z; scale is not removed)
        and its parameters (see the class); `origin` is the scene's local-frame origin.
        motion: the world matrices over the shutter (motion blur), or None."""
        m = np.array(world_from_camera, dtype=np.float64).reshape(4, 4)
        m[:3, 3] -= np.asarray(origin, dtype=np.float64)
        if motion is not None:
            motion = np.array(motion, dtype=np.float64).reshape(-1, 4, 4)
            motion[:, :3, 3] -= np.asarray(origin, dtype=np.float64)
        return cls(m, frustum, clip, orthographic, lens, panorama, motion)

    @classmethod
    def from_view_projection(cls, projection, world_from_camera, origin=(0.0, 0.0, 0.0), clip=None) -> "Camera":
        """From a perspective or orthographic projection matrix (camera space to clip space,
        OpenGL convention, as Blender's `Object.calc_matrix_camera` and a 3D view's
        window_matrix are) and the camera's world matrix. The image rectangle is read from
        the matrix's x and y rows, which float32 keeps to its precision; `clip` (start,
        end) gives the clipping range, which a float32 matrix loses for ranges of about 1e8
        and more. Without it, the range is read from the matrix."""
        p = np.asarray(projection, dtype=np.float64).reshape(4, 4)
        if not np.isfinite(p).all():
            raise ValueError("the projection matrix must be finite")
        scale = np.abs(p).max()
        zero = lambda *cells: all(abs(p[c]) <= 1e-9 * scale for c in cells)
        if not (zero((0, 1), (1, 0), (2, 0), (2, 1), (3, 0), (3, 1)) and p[0, 0] != 0 and p[1, 1] != 0):
            raise ValueError("not a perspective or orthographic projection matrix")
        # x_ndc = p00 u + c (u on the unit plane, or the view plane): u = (x_ndc - c) / p00
        # at x_ndc = -1 and +1; c is the x row's constant, in column 2 for a perspective
        # matrix (multiplied by -z = 1 on the unit plane) and column 3 for an orthographic one.
        if zero((0, 3), (1, 3), (3, 3)) and p[3, 2] == -1.0:
            orthographic, cx, cy = False, -p[0, 2], -p[1, 2]
            a, b = p[2, 2], p[2, 3]
            near_far = (b / (a - 1.0), b / (a + 1.0)) if a not in (1.0, -1.0) else None
        elif zero((0, 2), (1, 2), (3, 2)) and p[3, 3] == 1.0:
            orthographic, cx, cy = True, p[0, 3], p[1, 3]
            near_far = ((p[2, 3] + 1.0) / p[2, 2], (p[2, 3] - 1.0) / p[2, 2]) if p[2, 2] != 0 else None
        else:
            raise ValueError("not a perspective or orthographic projection matrix")
        x = ((-1.0 - cx) / p[0, 0], (1.0 - cx) / p[0, 0])
        y = ((-1.0 - cy) / p[1, 1], (1.0 - cy) / p[1, 1])
        if clip is None:
            if near_far is None or not all(math.isfinite(v) for v in near_far):
                raise ValueError("the projection matrix has lost its clipping range (a float32 matrix does for "
                                 "ranges of about 1e8 and more): give clip=(start, end)")
            clip = near_far
        return cls.from_frustum(world_from_camera, (*x, *y), clip, orthographic, origin)

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
        half_h = np.tan(np.radians(fov_y) / 2) if ortho_height is None else ortho_height / 2
        half_w = half_h * aspect
        return cls.from_frustum(w_c, (-half_w, half_w, -half_h, half_h), (near, far), ortho_height is not None)

    def rays(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """Pixel-centre rays (origins on the near plane, unit directions; float32, row-major
        from the top row): the core's own (Camera::ray), the rays `SplatCloud.render`
        traces, for use with `SplatCloud.trace`. The pinhole's rays: the lens is not
        sampled here. A pixel a panorama does not see has a zero direction."""
        if not (width > 0 and height > 0):
            raise ValueError(f"width and height must be positive, got {width}x{height}")
        origins = np.empty((width * height, 3), np.float32)
        directions = np.empty((width * height, 3), np.float32)
        _core.camera_rays(*self.native(), int(width), int(height), origins, directions)
        return origins, directions
