"""Analytic shapes and truth for the tests."""
from __future__ import annotations

import numpy as np


def fibonacci_sphere(n: int, radius: float = 1.0, centre=(0.0, 0.0, 0.0)):
    """n nearly evenly spaced points on a sphere, with their exact normals."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5 ** 0.5) * i
    normals = np.column_stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)])
    return normals * radius + np.asarray(centre, dtype=np.float64), normals


def ray_sphere(origins, directions, centre, radius):
    """Nearest positive hit distance per ray (inf on a miss); directions are unit."""
    oc = origins - np.asarray(centre)
    b = np.einsum("ij,ij->i", oc, directions)
    c = np.einsum("ij,ij->i", oc, oc) - radius ** 2
    disc = b * b - c
    t = np.full(len(origins), np.inf)
    ok = disc >= 0
    t[ok] = -b[ok] - np.sqrt(disc[ok])
    t[t <= 0] = np.inf
    return t


def angle_deg(a, b):
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.einsum("...i,...i->...", a, b), -1, 1)))
