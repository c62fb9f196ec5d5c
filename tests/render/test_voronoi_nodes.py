"""The Voronoi Texture node (native/nodes/voronoi.cpp) against a port of Blender 5's
definition written here in Python: every feature (F1, F2, Smooth F1, Distance to Edge,
N-Sphere Radius), dimension (1-D to 4-D), metric, fractal Voronoi (Detail, Roughness,
Lacunarity) and Normalize, every output (Distance, Color, Position, W, Radius).

The port follows the definitions, not the native code's structure: cells hashed by Jenkins'
lookup3 on the float cell (1-D) or by the PCG 2-D/3-D/4-D hashes of Jarzynski and Olano
(2020) on signed 32-bit integer cells (2-D to 4-D), as Blender 5 does; the search windows,
smoothing and octave sums as Cycles defines them; float64 arithmetic except in the hashes.
"""
import itertools
import math

import numpy as np
import pytest

from splat_tracer.render import nodes

RNG = np.random.default_rng(24)
M32 = 0xFFFFFFFF


# ---- hashes ---------------------------------------------------------------------------------

def _rot(x, k):
    return ((x << k) | (x >> (32 - k))) & M32


def _lookup3(*words):
    """Bob Jenkins' lookup3 of 1-3 words with Blender's seed (hash_uint, hash_uint2)."""
    a = b = c = (0xDEADBEEF + (len(words) << 2) + 13) & M32
    regs = [a, b, c]
    for i, w in enumerate(words):
        regs[i] = (regs[i] + w) & M32
    a, b, c = regs
    for x, y, k in (("c", "b", 14), ("a", "c", 11), ("b", "a", 25), ("c", "b", 16), ("a", "c", 4), ("b", "a", 14),
                    ("c", "b", 24)):
        r = {"a": a, "b": b, "c": c}
        r[x] ^= r[y]
        r[x] = (r[x] - _rot(r[y], k)) & M32
        a, b, c = r["a"], r["b"], r["c"]
    return c


def _bits(x):
    return int(np.float32(x).view(np.uint32))


def _unit_incl(h):
    return float(np.float32(h) * np.float32(1 / M32))


def _pcg(k):
    """PCG 2-D, 3-D or 4-D of integers, Blender's signed variant; components in 0..1."""
    n = len(k)
    v = [((int(c) & M32) * 1664525 + 1013904223) & M32 for c in k]

    def step():
        if n == 2:
            v[0] = (v[0] + v[1] * 1664525) & M32
            v[1] = (v[1] + v[0] * 1664525) & M32
        elif n == 3:
            v[0] = (v[0] + v[1] * v[2]) & M32
            v[1] = (v[1] + v[2] * v[0]) & M32
            v[2] = (v[2] + v[0] * v[1]) & M32
        else:
            v[0] = (v[0] + v[1] * v[3]) & M32
            v[1] = (v[1] + v[2] * v[0]) & M32
            v[2] = (v[2] + v[0] * v[1]) & M32
            v[3] = (v[3] + v[1] * v[2]) & M32

    step()
    for i in range(n):
        signed = v[i] - (1 << 32) if v[i] >> 31 else v[i]
        v[i] ^= (signed >> 16) & M32
    step()
    return [float(np.float32(c & 0x7FFFFFFF) * np.float32(1 / 0x7FFFFFFF)) for c in v]


def _cell_hash(cell):
    """The cell's random offset in 0..1 per axis."""
    if len(cell) == 1:
        return [_unit_incl(_lookup3(_bits(cell[0])))]
    return _pcg(cell)


def _cell_colour(cell):
    if len(cell) == 1:
        k = _bits(cell[0])
        return np.array([_unit_incl(_lookup3(k)), _unit_incl(_lookup3(k, _bits(1.0))),
                         _unit_incl(_lookup3(k, _bits(2.0)))])
    if len(cell) == 2:
        return np.array(_pcg(list(cell) + [0]))
    return np.array(_pcg(cell)[:3])


# ---- one octave -----------------------------------------------------------------------------

def _offsets(n, reach):
    """The window's offsets, the first axis fastest (Cycles' loop order)."""
    for t in itertools.product(range(-reach, reach + 1), repeat=n):
        yield np.array(t[::-1])


def _dist(a, b, metric, exponent):
    d = np.abs(np.asarray(a) - np.asarray(b))
    if len(d) == 1:
        return float(d[0])
    return float({"EUCLIDEAN": lambda: np.sqrt((d * d).sum()), "MANHATTAN": d.sum, "CHEBYSHEV": d.max,
                  "MINKOWSKI": lambda: (d ** exponent).sum() ** (1 / exponent)}[metric]())


class Octave:
    def __init__(self, p, metric, exponent, randomness):
        self.cell = np.floor(p)
        self.local = np.asarray(p) - self.cell
        self.metric, self.exponent, self.randomness = metric, exponent, randomness

    def point(self, off):
        return off + np.array(_cell_hash(self.cell + off)) * self.randomness

    def colour(self, off):
        return _cell_colour(self.cell + off)

    def dist(self, a, b):
        return _dist(a, b, self.metric, self.exponent)

    def nearest(self):
        """(distance, offset, point) of every point of the 3^n window, nearest first."""
        found = [(self.dist(self.point(o), self.local), k, o, self.point(o))
                 for k, o in enumerate(_offsets(len(self.cell), 1))]
        found.sort(key=lambda t: (t[0], t[1]))
        return [(d, o, p) for d, _, o, p in found]

    def f1(self):
        d, o, p = self.nearest()[0]
        return d, self.colour(o), p + self.cell

    def f2(self):
        d, o, p = self.nearest()[1]
        return d, self.colour(o), p + self.cell

    def smooth_f1(self, smoothness):
        # Quilez's smooth minimum over the 5^n window, colour and position blended alike,
        # with Blender's corrections.
        distance, colour, position, first = 0.0, np.zeros(3), np.zeros(len(self.cell)), True
        for o in _offsets(len(self.cell), 2):
            p = self.point(o)
            d = self.dist(p, self.local)
            if first:
                h, first = 1.0, False
            else:
                x = 0.5 + 0.5 * (distance - d) / smoothness
                h = 0.0 if x < 0 else 1.0 if x >= 1 else x * x * (3 - 2 * x)
            corr = smoothness * h * (1 - h)
            distance = distance + h * (d - distance) - corr
            corr /= 1 + 3 * smoothness
            colour = colour + h * (self.colour(o) - colour) - corr
            position = position + h * (p - position) - corr
        return distance, colour, position + self.cell

    def edge(self):
        if len(self.cell) == 1:
            mid, left, right = (self.point(np.array([k]))[0] for k in (0, -1, 1))
            x = self.local[0]
            return min(abs((mid + left) / 2 - x), abs((mid + right) / 2 - x))
        # The distance to the nearest bisector between the nearest point and another.
        vecs = [self.point(o) - self.local for o in _offsets(len(self.cell), 1)]
        closest = min(vecs, key=lambda v: v @ v)
        best = math.inf
        for v in vecs:
            across = v - closest
            if across @ across > 1e-4:
                best = min(best, float((closest + v) / 2 @ (across / np.linalg.norm(across))))
        return best

    def radius(self):
        n = len(self.cell)
        euclid = [(float(np.linalg.norm(self.point(o) - self.local)), k, o)
                  for k, o in enumerate(_offsets(n, 1))]
        _, _, co = min(euclid, key=lambda t: (t[0], t[1]))
        c = self.point(co)
        around = [self.point(co + o) for o in _offsets(n, 1) if o.any()]
        nearest = min(around, key=lambda q: float(np.linalg.norm(q - c)))
        return float(np.linalg.norm(nearest - c)) / 2


# ---- the node -------------------------------------------------------------------------------

def voronoi(vector, w, dims, feature, metric="EUCLIDEAN", scale=1.0, detail=0.0, roughness=0.5,
            lacunarity=2.0, smoothness=1.0, exponent=1.0, randomness=1.0, normalize=False):
    """Blender 5's Voronoi Texture node: (distance, colour, position, w, radius)."""
    detail, roughness = min(max(detail, 0.0), 15.0), min(max(roughness, 0.0), 1.0)
    randomness, smoothness = min(max(randomness, 0.0), 1.0), min(max(smoothness / 2, 0.0), 0.5)
    v = np.asarray(vector, float) * scale
    coord = {1: [w * scale], 2: list(v[:2]), 3: list(v), 4: list(v) + [w * scale]}[dims]
    coord = np.array(coord)

    def octave_at(s):
        return Octave(coord * s, metric, exponent, randomness)

    single = detail == 0 or roughness == 0
    octaves = 1 if single else math.ceil(detail) + 1
    zero3 = np.zeros(3)
    if feature == "N_SPHERE_RADIUS":
        return 0.0, zero3, zero3, 0.0, octave_at(1.0).radius()
    if feature == "DISTANCE_TO_EDGE":
        max_distance = 0.5 + 0.5 * randomness
        amplitude, max_amp, s, d = 1.0, max_distance, 1.0, 8.0
        for i in range(octaves):
            o = octave_at(s).edge()
            if single:
                d = o
                break
            # An octave blends in its minimum by its amplitude (the last by Detail's fraction too).
            if i <= detail:
                max_amp += amplitude * (max_distance / s - max_amp)
                d += amplitude * (min(d, o / s) - d)
                s, amplitude = s * lacunarity, amplitude * roughness
            else:
                r = detail - math.floor(detail)
                max_amp += r * (max_amp + amplitude * (max_distance / s - max_amp) - max_amp)
                d += r * (min(d, d + amplitude * (min(d, o / s) - d)) - d)
        return (d / max_amp if normalize else d), zero3, zero3, 0.0, 0.0
    corner = np.full(dims, 0.5 + 0.5 * randomness)
    max_distance = _dist(np.zeros(dims), corner, metric, exponent) * (2 if feature == "F2" else 1)
    amplitude, max_amp, s = 1.0, 0.0, 1.0
    dist, colour, position = 0.0, np.zeros(3), np.zeros(dims)
    for i in range(octaves):
        oc = octave_at(s)
        if feature == "F2":
            od, ocol, opos = oc.f2()
        elif feature == "SMOOTH_F1" and smoothness != 0:
            od, ocol, opos = oc.smooth_f1(smoothness)
        else:
            od, ocol, opos = oc.f1()
        if single:
            max_amp, dist, colour, position = 1.0, od, ocol, opos
            break
        if i <= detail:
            max_amp += amplitude
            dist += od * amplitude
            colour = colour + ocol * amplitude
            position = position + amplitude * (opos / s - position)
            s, amplitude = s * lacunarity, amplitude * roughness
        else:
            r = detail - math.floor(detail)
            max_amp += r * amplitude
            dist += r * od * amplitude
            colour = colour + r * ocol * amplitude
            position = position + r * amplitude * (opos / s - position)
    if normalize:
        dist /= max_amp * max_distance
        colour = colour / max_amp
    position = position / scale if scale != 0 else position * 0
    pos3 = np.concatenate([position, np.zeros(3)])[:3] if dims > 1 else zero3
    w_out = position[-1] if dims in (1, 4) else 0.0  # W: the 4th coordinate (1-D's only one)
    return dist, colour, pos3, w_out, 0.0


def run_voronoi(vectors, ws, dims, feature, metric="EUCLIDEAN", scale=1.0, detail=0.0, roughness=0.5,
                lacunarity=2.0, smoothness=1.0, exponent=1.0, randomness=1.0, normalize=False):
    """The native node at each (vector, w): rows of (distance, colour 3, position 3, w, radius)."""
    b = nodes.Builder()
    out = b.register(width=9)
    params = b.register((scale, detail, roughness, lacunarity, smoothness, exponent, randomness, float(normalize)), 8)
    vector, w = b.global_("OBJECT"), b.global_("GENERATED")  # W: the generated coordinates' x
    b.emit("VORONOI", out, vector, w, params, nodes.VORONOI_METRICS.index(metric),
           nodes.VORONOI_FEATURES.index(feature), dims - 1)
    gen = np.zeros((len(ws), 3), np.float32)
    gen[:, 0] = ws
    return nodes.run(b.program(), len(vectors), object=vectors, generated=gen)[:, out:out + 9]


def check(n=12, **kw):
    vectors = RNG.uniform(-3, 3, (n, 3)).astype(np.float32)
    ws = RNG.uniform(-3, 3, n).astype(np.float32)
    got = run_voronoi(vectors, ws, **kw)
    for v, w, row in zip(vectors.astype(float), ws.astype(float), got):
        d, colour, position, w_out, radius = voronoi(v, w, **kw)
        want = np.concatenate([[d], colour, position, [w_out, radius]])
        np.testing.assert_allclose(row, want, atol=2e-5, rtol=2e-5, err_msg=f"{kw} at {v}, w {w}")
    return got


FEATURES = nodes.VORONOI_FEATURES


@pytest.mark.parametrize("dims", [1, 2, 3, 4])
@pytest.mark.parametrize("feature", FEATURES)
def test_every_feature_in_every_dimension(feature, dims):
    got = check(dims=dims, feature=feature, scale=1.3, randomness=0.8, smoothness=0.6)
    # Each feature fills its own outputs only, as Cycles does.
    if feature == "N_SPHERE_RADIUS":
        assert (got[:, :8] == 0).all() and (got[:, 8] > 0).all()
    elif feature == "DISTANCE_TO_EDGE":
        assert (got[:, 1:] == 0).all() and (got[:, 0] > 0).all()
    else:
        assert (got[:, 8] == 0).all() and (got[:, 1:4] > 0).any()
        assert (got[:, 7] != 0).all() == (dims in (1, 4))


@pytest.mark.parametrize("dims", [2, 3, 4])
@pytest.mark.parametrize("metric", ["MANHATTAN", "CHEBYSHEV", "MINKOWSKI"])
@pytest.mark.parametrize("feature", ["F1", "F2", "SMOOTH_F1"])
def test_metrics_and_exponent(metric, feature, dims):
    check(dims=dims, feature=feature, metric=metric, scale=2.1, exponent=1.5, randomness=1.0, smoothness=0.4)


def test_one_dimension_ignores_the_metric():
    vectors, ws = np.zeros((6, 3), np.float32), np.linspace(-2, 2, 6).astype(np.float32)
    e = run_voronoi(vectors, ws, dims=1, feature="F2", metric="EUCLIDEAN", scale=1.7)
    m = run_voronoi(vectors, ws, dims=1, feature="F2", metric="MINKOWSKI", exponent=0.7, scale=1.7)
    np.testing.assert_array_equal(e, m)


@pytest.mark.parametrize("dims", [1, 2, 3, 4])
@pytest.mark.parametrize("feature", ["F1", "F2", "SMOOTH_F1", "DISTANCE_TO_EDGE"])
@pytest.mark.parametrize("normalize", [False, True])
def test_fractal_voronoi(feature, dims, normalize):
    # Detail 2.5: two whole octaves after the first and half of a fourth (Detail's fraction).
    check(n=6, dims=dims, feature=feature, scale=1.1, detail=2.5, roughness=0.6, lacunarity=2.3, smoothness=0.5,
          randomness=0.9, normalize=normalize)


@pytest.mark.parametrize("feature", ["F1", "F2", "DISTANCE_TO_EDGE"])
def test_normalize_without_detail(feature):
    check(dims=3, feature=feature, metric="MANHATTAN", scale=1.5, randomness=0.7, normalize=True)


def test_inputs_are_clamped_as_cycles_clamps_them():
    # Randomness above 1, Detail above 15, Roughness above 1, Smoothness above 1: held.
    check(n=4, dims=2, feature="SMOOTH_F1", detail=40.0, roughness=3.0, randomness=2.0, smoothness=5.0)
    # Roughness 0 (or Detail 0): one octave whatever the Detail.
    a = run_voronoi(np.ones((1, 3), np.float32) * 0.3, np.zeros(1, np.float32), dims=3, feature="F1",
                    detail=3.0, roughness=0.0)
    b = run_voronoi(np.ones((1, 3), np.float32) * 0.3, np.zeros(1, np.float32), dims=3, feature="F1")
    np.testing.assert_array_equal(a, b)


def test_a_wrong_feature_is_told_apart():
    """The port tells F1 and F2 apart (the tests above could not pass by accident)."""
    vectors = RNG.uniform(-3, 3, (8, 3)).astype(np.float32)
    got = run_voronoi(vectors, np.zeros(8, np.float32), dims=3, feature="F2")
    f1 = [voronoi(v, 0.0, 3, "F1")[0] for v in vectors.astype(float)]
    assert (got[:, 0] > np.array(f1) + 1e-3).all()


def test_far_and_non_finite_coordinates_stay_finite_or_defined():
    vectors = np.array([[3e9, -3e9, 1e30], [np.inf, 0, 0], [np.nan, 1, 2]], np.float32)
    for feature in FEATURES:
        for dims in (2, 3, 4):
            run_voronoi(vectors, np.array([1e30, np.inf, np.nan], np.float32), dims=dims, feature=feature,
                        detail=2.0)
