"""Errors of a rendering against the truth, per pixel centre."""
from __future__ import annotations

import numpy as np

# A pixel shows the wrong surface when its depth is off by more than this many splat radii:
# within a layer's thickness (about a radius) a depth error is the position of the right
# surface a little off; beyond a few radii it is another surface (a fringe disc, a disc from
# behind), whatever the scale of the scene.
WRONG_SURFACE_RADII = 3.0


def score(truth, hit, depth, normal, directions, splat_radius: float) -> dict:
    """hit (P,), depth (P,) planar, normal (P,3) as rendered; directions (P,3) unit rays;
    splat_radius: the cloud's median splat radius."""
    both = hit & truth.hit
    n = normal[both].astype(np.float64)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    n *= np.where(np.einsum("ij,ij->i", n, directions[both]) > 0, -1.0, 1.0)[:, None]
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, truth.smooth_normal[both]), -1, 1)))
    abs_depth = np.abs(depth[both] - truth.depth[both])
    rel_depth = abs_depth / truth.size
    return {
        "silhouette_px": int((hit != truth.hit).sum()),
        "silhouette_pct": float(100.0 * (hit != truth.hit).sum() / max(truth.hit.sum(), 1)),
        # The two kinds apart: holes and rejected surface, against fringes and fattening.
        "missing_px": int((truth.hit & ~hit).sum()),
        "extra_px": int((hit & ~truth.hit).sum()),
        "normal_mean_deg": float(angle.mean()) if both.any() else float("nan"),
        "normal_p95_deg": float(np.percentile(angle, 95)) if both.any() else float("nan"),
        "depth_mean_rel": float(rel_depth.mean()) if both.any() else float("nan"),
        "wrong_surface_pct": (float(100.0 * (abs_depth > WRONG_SURFACE_RADII * splat_radius).mean())
                              if both.any() else float("nan")),
    }
