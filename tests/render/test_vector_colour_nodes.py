"""Vector Rotate, Map Range (vector), HSL, Wavelength, curve extrapolation and object space
(issue 24): each instruction against values computed here from Blender's definitions (numpy
rotation matrices, colorsys, the CIE table), not from the core's code."""
from __future__ import annotations

import colorsys
import math
import pathlib
import re

import numpy as np
import pytest

from splat_tracer.render import nodes
from test_nodes import run_op

RNG = np.random.default_rng(24)


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _axis_angle(axis, angle):
    """The rotation matrix about `axis` (any length) by `angle`, from the exponential of its
    cross-product matrix (right-handed)."""
    k = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _rotate(kind, invert, v, center, axis, angle, euler):
    if kind == "EULER_XYZ":
        m = _rz(euler[2]) @ _ry(euler[1]) @ _rx(euler[0])  # X first, then Y, then Z
        m = m.T if invert else m
    else:
        axis = {"X_AXIS": (1, 0, 0), "Y_AXIS": (0, 1, 0), "Z_AXIS": (0, 0, 1)}.get(kind, axis)
        m = _axis_angle(axis, -angle if invert else angle)
    return m @ (np.asarray(v) - center) + center


@pytest.mark.parametrize("invert", [False, True])
@pytest.mark.parametrize("kind", nodes.VECTOR_ROTATE_TYPES)
def test_vector_rotate_matches_rotation_matrices(kind, invert):
    for _ in range(5):
        v, center, axis, euler = (RNG.uniform(-2, 2, 3) for _ in range(4))
        angle = float(RNG.uniform(-4, 4))
        got = run_op("VECTOR_ROTATE", [(v, 3), (center, 3), (axis, 3), (angle, 1), (euler, 3)], [3],
                     nodes.VECTOR_ROTATE_TYPES.index(kind) + 5 * invert)[0][0]
        np.testing.assert_allclose(got, _rotate(kind, invert, v, center, axis, angle, euler), atol=2e-5)


def test_vector_rotate_about_a_zero_axis_leaves_the_vector():
    got = run_op("VECTOR_ROTATE", [((1, 2, 3), 3), ((0.5, 0, 0), 3), ((0, 0, 0), 3), (1.0, 1), ((0, 0, 0), 3)], [3],
                 nodes.VECTOR_ROTATE_TYPES.index("AXIS_ANGLE"))[0][0]
    np.testing.assert_allclose(got, (1, 2, 3))


def test_a_wrong_rotation_sense_is_told_apart():
    v, axis = np.array([1.0, 0.0, 0.0]), (0, 0, 1)
    got = run_op("VECTOR_ROTATE", [(v, 3), ((0, 0, 0), 3), (axis, 3), (0.5, 1), ((0, 0, 0), 3)], [3], 0)[0][0]
    assert np.abs(got - _axis_angle(axis, -0.5) @ v).max() > 0.5  # the opposite sense is far off
    np.testing.assert_allclose(got, (math.cos(0.5), math.sin(0.5), 0), atol=1e-6)


def _hsl(rgb):
    h, l, s = colorsys.rgb_to_hls(*rgb)
    return h, s, min(l, 1.0)  # Blender caps lightness at 1 (for colours over 1)


def test_rgb_to_hsl_matches_colorsys():
    colours = list(RNG.uniform(0, 1, (40, 3))) + [(0.5, 0.5, 0.5), (1, 0, 0), (0, 1, 1), (0.2, 0.2, 0.9)]
    for c in colours:
        got = run_op("RGB_TO_HSL", [(c, 3)], [3])[0][0]
        np.testing.assert_allclose(got, _hsl(c), atol=2e-6)


def test_hsl_to_rgb_matches_colorsys_and_round_trips():
    for h, s, l in RNG.uniform(0, 1, (40, 3)):
        got = run_op("HSL_TO_RGB", [((h, s, l), 3)], [3])[0][0]
        np.testing.assert_allclose(got, colorsys.hls_to_rgb(h, l, s), atol=2e-6)
        back = run_op("RGB_TO_HSL", [(got, 3)], [3])[0][0]
        if s > 1e-3 and 1e-3 < l < 1 - 1e-3:
            np.testing.assert_allclose(back, (h, s, l), atol=5e-5)


def _cie_table():
    """The CIE 1931 2-degree table as the core's header carries it (rows of 5 nm from 360)."""
    text = (pathlib.Path(nodes.__file__).parents[1] / "native" / "nodes" / "cie1931.h").read_text()
    rows = re.findall(r"\{([-0-9.e+f, ]+)\},\s*// (\d+) nm", text)
    return {int(nm): np.array([float(x.rstrip("f")) for x in row.split(",")]) for row, nm in rows}


# XYZ (D65) to linear Rec. 709 (IEC 61966-2-1), Blender's XYZ role to its scene-linear space.
XYZ_TO_REC709 = np.array([[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560],
                          [0.0556434, -0.2040259, 1.0572252]])


def _wavelength(nm):
    if not 380 <= nm < 780:
        return np.zeros(3)
    table = _cie_table()
    lo = 380 + 5 * math.floor((nm - 380) / 5)
    t = (nm - lo) / 5
    xyz = (1 - t) * table[lo] + t * table[lo + 5]
    return np.maximum(XYZ_TO_REC709 @ xyz / 2.52, 0)  # Cycles' scale: every channel <= 1


@pytest.mark.parametrize("nm", [350, 379.9, 380, 444.4, 500, 555, 587.3, 611, 700, 779.9, 780, 900])
def test_wavelength_matches_the_cie_table(nm):
    got = run_op("WAVELENGTH", [(nm, 1)], [3])[0][0]
    np.testing.assert_allclose(got, _wavelength(nm), atol=2e-6)


def test_wavelength_spectrum_stays_within_one():
    got = np.array([run_op("WAVELENGTH", [(nm, 1)], [3])[0][0] for nm in np.arange(380, 780, 2.5)])
    assert got.min() >= 0 and 0.9 < got.max() <= 1.0


def _table_program(rows, lo, hi, extrapolate, values, fac=1.0):
    b = nodes.Builder()
    out = b.register(width=3)
    table = b.table([list(r) + [0.0] for r in rows])
    span = b.register((lo, hi, 0.0), 3)
    colour = b.register(values, 3)
    b.emit("CURVES", out, b.register(fac), colour, table, len(rows), span, extrapolate)
    return nodes.run(b.program())[0, out:out + 3]


@pytest.mark.parametrize("extrapolate", [0, 1])
def test_curves_beyond_their_range(extrapolate):
    """A table over -1..2 (the curve's points' range): inside, read linearly between rows;
    beyond, on along the end rows' slope (Extrapolated) or held (Horizontal)."""
    xs = np.linspace(-1, 2, 256)
    rows = np.stack([xs ** 2, 2 * xs, np.sin(xs)], axis=1)
    values = np.array([-1.5, 2.75, 0.3])
    got = _table_program(rows, -1.0, 2.0, extrapolate, values)
    f = (values + 1) / 3 * 255
    want = []
    for k, x in enumerate(values):
        column = rows[:, k]
        if x < -1:
            slope = (column[0] - column[1]) if extrapolate else 0.0
            want.append(column[0] + slope * (-f[k]))
        elif x > 2:
            slope = (column[-1] - column[-2]) if extrapolate else 0.0
            want.append(column[-1] + slope * (f[k] - 255))
        else:
            want.append(np.interp(f[k], np.arange(256), column))
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    if extrapolate:  # linear beyond the ends: 2x at -1.5 is -3, well away from the held -2
        assert abs(got[1] - 5.5) < 1e-3


def _vector_map_range(v, fmin, fmax, tmin, tmax, steps, mode, clamp):
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(fmax != fmin, (v - fmin) / np.where(fmax != fmin, fmax - fmin, 1), 0.0)
    if mode == "STEPPED":
        f = np.where(steps > 0, np.floor(f * (steps + 1)) / np.where(steps > 0, steps, 1), 0.0)
    elif mode == "SMOOTHSTEP":
        t = np.clip(f, 0, 1)
        f = t * t * (3 - 2 * t)
    elif mode == "SMOOTHERSTEP":
        t = np.clip(f, 0, 1)
        f = t ** 3 * (t * (6 * t - 15) + 10)
    r = tmin + f * (tmax - tmin)
    if clamp and mode in ("LINEAR", "STEPPED"):
        r = np.clip(r, np.minimum(tmin, tmax), np.maximum(tmin, tmax))
    return r


@pytest.mark.parametrize("clamp", [0, 1])
@pytest.mark.parametrize("mode", nodes.MAP_RANGE_MODES)
def test_vector_map_range_per_component(mode, clamp):
    for _ in range(6):
        v = RNG.uniform(-2, 3, 3)
        fmin, fmax, tmin, tmax = (RNG.uniform(-1, 2, 3) for _ in range(4))
        fmax[0] = fmin[0]  # a zero source range: To Min (Cycles divides safely)
        steps = np.array([4.0, 0.0, 2.5])
        b = nodes.Builder()
        out = b.register(width=3)
        value = b.register(v, 3)
        params = b.table(np.concatenate([fmin, fmax, tmin, tmax, steps]))
        b.emit("VECTOR_MAP_RANGE", out, value, params, nodes.MAP_RANGE_MODES.index(mode), clamp)
        got = nodes.run(b.program())[0, out:out + 3]
        want = _vector_map_range(v, fmin, fmax, tmin, tmax, steps, mode, clamp)
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
        assert abs(got[0] - tmin[0]) < 1e-6 or mode == "STEPPED"


def test_object_space_moves_points_not_vectors():
    """With an unrotated object (identity normal matrix), a point's object coordinates are
    the shading point's plus the offset from it; a vector and a normal stay."""
    P, obj = np.array([1.0, 2.0, 3.0]), np.array([-0.5, 0.25, 4.0])
    v = np.array([1.5, 1.0, 2.0])
    to_object = run_op("OBJECT_SPACE", [(v, 3)], [3], 0, P=P, object=obj)[0][0]
    np.testing.assert_allclose(to_object, obj + v - P, atol=1e-6)
    back = run_op("OBJECT_SPACE", [(to_object, 3)], [3], 3, P=P, object=obj)[0][0]
    np.testing.assert_allclose(back, v, atol=1e-6)
    np.testing.assert_allclose(run_op("OBJECT_SPACE", [(v, 3)], [3], 1, P=P, object=obj)[0][0], v, atol=1e-6)
    np.testing.assert_allclose(run_op("OBJECT_SPACE", [(v, 3)], [3], 2, P=P, object=obj)[0][0],
                               v / np.linalg.norm(v), atol=1e-6)


# ---------------------------------------------------------------- Gabor Texture

def _h(*words):
    """Blender's hash of float words to 0..1 (lookup3 of their bits: test_noise_nodes' port)."""
    from test_noise_nodes import _hash, _unit
    return float(_unit(_hash(*(np.float32(w).view(np.uint32) for w in words))))


def _gabor_reference(co, scale, frequency, anisotropy, angle, direction, three_d):
    """Cycles 5's Gabor noise written out in float64 from its definition (svm/gabor.h)."""
    c = np.asarray(co, np.float64) * scale
    iso = 1 - min(max(anisotropy, 0), 1)
    frequency = max(0.001, frequency)
    n = 3 if three_d else 2
    base, local = np.floor(c[:n]), c[:n] - np.floor(c[:n])
    o3 = np.asarray(direction, np.float64) / np.linalg.norm(direction)
    total = 0j
    for offset in np.ndindex(*(3,) * n):
        off = np.array(offset[::-1], np.float64) - 1  # x fastest, as the loops nest
        cell, p = base + off, local - off
        cell32 = [np.float32(v) for v in cell]
        for i in range(8):
            k = np.float32(3 * i)
            if three_d:
                x, y, z = cell32
                if iso == 0:
                    o = o3
                else:
                    inc, az = math.acos(o3[2]), math.copysign(1, o3[1] if o3[1] != 0 else 1) * math.acos(
                        o3[0] / math.hypot(o3[0], o3[1]))
                    inc += _h(x, y, z, k) * math.pi * iso
                    az += _h(z, x, k, y) * math.pi * iso
                    o = np.array([math.sin(inc) * math.cos(az), math.sin(inc) * math.sin(az), math.cos(inc)])
                k1 = k + 1
                centre = np.array([_h(x, y, z, k1), _h(z, x, k1, y), _h(k1, z, y, x)])
                weight = -1 if _h(x, y, z, k + 2) < 0.5 else 1
                fvec = frequency * o
            else:
                x, y = cell32
                a = angle + (_h(x, y, k) - 0.5) * math.pi * iso
                centre = np.array([_h(x, y, k + 1), _h(k + 1, x, y)])
                weight = -1 if _h(x, y, k + 2) < 0.5 else 1
                fvec = frequency * np.array([math.cos(a), math.sin(a)])
            d = p - centre
            r2 = float(d @ d)
            if r2 >= 1:
                continue
            envelope = math.exp(-math.pi * r2) * (0.5 + 0.5 * math.cos(math.pi * r2))
            total += weight * envelope * np.exp(2j * math.pi * float(d @ fvec))
    deviation = math.sqrt(8 * 0.5 * (1 / (4 * math.sqrt(2)) if three_d else 0.25))
    norm = 6 * deviation
    return total.imag / norm * 0.5 + 0.5, (math.atan2(total.imag, total.real) + math.pi) / (2 * math.pi), abs(total) / norm


@pytest.mark.parametrize("three_d", [False, True])
@pytest.mark.parametrize("anisotropy", [0.0, 0.6, 1.0])
def test_gabor_matches_its_definition(three_d, anisotropy):
    for _ in range(6):
        co = RNG.uniform(-3, 3, 3)
        scale, frequency, angle = float(RNG.uniform(0.5, 4)), float(RNG.uniform(0.3, 4)), float(RNG.uniform(-3, 3))
        direction = RNG.uniform(-1, 1, 3)
        b = nodes.Builder()
        out = b.register(width=3)
        params = b.table([scale, frequency, anisotropy, angle])
        b.emit("GABOR", out, b.register(co, 3), params, b.register(direction, 3), int(three_d))
        got = nodes.run(b.program())[0, out:out + 3]
        want = _gabor_reference(co, scale, frequency, anisotropy, angle, direction, three_d)
        assert abs(got[0] - want[0]) < 2e-4 and abs(got[2] - want[2]) < 2e-4
        if want[2] > 1e-3:  # the phase is defined where the intensity is not 0
            assert abs((got[1] - want[1] + 0.5) % 1 - 0.5) < 2e-3
        assert 0 <= got[1] <= 1
