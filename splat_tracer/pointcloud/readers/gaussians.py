"""3D and 2D Gaussian-splatting captures (PLY files of trained Gaussians) as splats.

A 3D Gaussian Splatting PLY (Kerbl et al. 2023) has per vertex: x y z, the DC spherical-
harmonic colour f_dc_0..2 (and view-dependent f_rest_*), opacity as a logit, scale_0..2 as
log standard deviations along the Gaussian's axes, and rot_0..3 a unit quaternion (w, x, y,
z; stored unnormalised) whose rotation matrix's columns are those axes. A 2D Gaussian
Splatting PLY (Huang et al. 2024) is the same with two scales: each Gaussian is a flat
surfel spanned by the rotation's first two axes.

As splats:
- colour = 0.5 + C0 * f_dc (C0 = 0.28209479177387814, the degree-0 SH basis), clipped to
  0..1. The captures are trained against sRGB images, so this is a display value and is
  converted to scene-linear like every file colour. f_rest_* (view-dependent colour) are
  ignored, said in the notes.
- normal = the rotation's axis of the smallest scale (3DGS), the third axis (2DGS). Its sign
  is arbitrary in the file: the importer orients the normals (`PointCloud.oriented` False).
- radius = 2 * sqrt(s_a * s_b) with s_a, s_b the two larger standard deviations: the disc of
  the same area as the Gaussian's 2-sigma ellipse (which holds 86 % of its weight). A disc
  is opaque out to its rim where the Gaussian fades; 1 sigma leaves holes between trained
  Gaussians, 3 sigma (the rasteriser's cut-off) turns faint tails into opaque blobs. The
  equal-area disc keeps an elongated Gaussian's coverage without its length.
- alpha = sigmoid(opacity), the points' alpha (the fourth channel of splat_color).
"""
from __future__ import annotations

import numpy as np

from ...util.matrices import quaternion_matrices
from ..cloud import CloudFileError, PointCloud, make_cloud, srgb_to_linear

C0 = 0.28209479177387814
GAUSSIAN_FIELDS = ("f_dc_0", "f_dc_1", "f_dc_2", "opacity", "rot_0", "rot_1", "rot_2", "rot_3",
                   "scale_0", "scale_1")
SIGMAS = 2.0  # the disc's radius in standard deviations (see the module's text)


def is_gaussian(names) -> bool:
    """A vertex element with any of the Gaussian-splatting properties is read as one
    (and then must have all of them)."""
    return any(n.startswith(("f_dc_", "scale_", "rot_")) for n in names) or "opacity" in names


def read_gaussians(path: str, v, names) -> PointCloud:
    missing = [f for f in GAUSSIAN_FIELDS if f not in names]
    if missing:
        raise CloudFileError(f"{path}: a Gaussian-splatting PLY (it has "
                             f"{', '.join(sorted(n for n in names if n in GAUSSIAN_FIELDS or n == 'scale_2'))}) "
                             f"lacks the propert{'ies' if len(missing) > 1 else 'y'} {', '.join(missing)}")
    three_d = "scale_2" in names
    col = lambda c: np.asarray(v[c], dtype=np.float64)  # noqa: E731
    pos = np.column_stack([col(c) for c in "xyz"])
    q = np.column_stack([col(f"rot_{i}") for i in range(4)])
    log_scales = np.column_stack([col(f"scale_{i}") for i in range(3 if three_d else 2)])
    with np.errstate(over="ignore", invalid="ignore"):
        qlen = np.linalg.norm(q, axis=1)
        scales = np.exp(log_scales)
        opacity = 1.0 / (1.0 + np.exp(-col("opacity")))
    # A Gaussian without a rotation or with an unusable scale cannot be a disc: dropped and
    # counted like a point with an unusable normal (its normal is made NaN below).
    ok = np.isfinite(qlen) & (qlen > 0) & np.isfinite(scales).all(axis=1) & (scales > 0).all(axis=1)
    ok &= np.isfinite(opacity)
    q = q / np.where(ok, qlen, 1.0)[:, None]
    axes = quaternion_matrices(np.where(ok[:, None], q, [1.0, 0.0, 0.0, 0.0]))
    safe_scales = np.where(ok[:, None], scales, 1.0)
    if three_d:
        order = np.argsort(safe_scales, axis=1)  # smallest first
        rows = np.arange(len(pos))
        normals = axes[rows, :, order[:, 0]]
        s_a, s_b = safe_scales[rows, order[:, 1]], safe_scales[rows, order[:, 2]]
    else:
        normals = axes[:, :, 2]
        s_a, s_b = safe_scales[:, 0], safe_scales[:, 1]
    normals = np.where(ok[:, None], normals, np.nan)
    radii = (SIGMAS * np.sqrt(s_a * s_b)).astype(np.float32)
    dc = np.column_stack([col(f"f_dc_{i}") for i in range(3)])
    rgb = np.clip(np.nan_to_num(0.5 + C0 * dc, nan=0.0), 0.0, 1.0)
    colours = np.column_stack([srgb_to_linear(rgb), np.where(ok, opacity, 1.0)]).astype(np.float32)
    notes = []
    rest = sum(1 for n in names if n.startswith("f_rest_"))
    if rest:
        notes.append(f"the {rest} view-dependent colour coefficients (f_rest_*) are ignored: each splat has its "
                     "Gaussian's base (DC) colour")
    cloud = make_cloud(path, pos, normals, colours, radii, drop_non_finite=True, format="3DGS" if three_d else "2DGS",
                       oriented=False, notes=notes)
    return cloud
