"""The Noise Texture node (native/nodes/noise.cpp) in 1, 2, 3 and 4 dimensions and its five
fractal types, against a numpy port written here from Blender's definitions (Cycles'
kernel/svm/noise.h, fractal_noise.h, noisetex.h): Jenkins' lookup3 hash, improved Perlin
noise as a weighted sum over the cell's corners, the fractal sums, distortion and the
colour's offset seeds. Float32 throughout, as the kernel computes; the interpolation is
summed in another order here, hence the small tolerances."""
import numpy as np
import pytest

from splat_tracer.render import nodes

RNG = np.random.default_rng(11)
F = np.float32
U = np.uint32


def _rot(x, k):
    return (x << U(k)) | (x >> U(32 - k))


def _final(a, b, c):
    c = (c ^ b) - _rot(b, 14)
    a = (a ^ c) - _rot(c, 11)
    b = (b ^ a) - _rot(a, 25)
    c = (c ^ b) - _rot(b, 16)
    a = (a ^ c) - _rot(c, 4)
    b = (b ^ a) - _rot(a, 14)
    c = (c ^ b) - _rot(b, 24)
    return c


def _hash(*words):
    """Blender's hash_uint .. hash_uint4 of uint32 arrays (lookup3, seeded by the word count)."""
    with np.errstate(over="ignore"):
        words = [np.asarray(w, np.uint32) for w in words]
        a = b = c = np.full(np.broadcast(*words).shape, (0xDEADBEEF + (len(words) << 2) + 13) & 0xFFFFFFFF, U)
        if len(words) == 4:
            a, b, c = a + words[0], b + words[1], c + words[2]
            a = (a - c) ^ _rot(c, 4); c = c + b  # noqa: E702  (lookup3's mix)
            b = (b - a) ^ _rot(a, 6); a = a + c  # noqa: E702
            c = (c - b) ^ _rot(b, 8); b = b + a  # noqa: E702
            a = (a - c) ^ _rot(c, 16); c = c + b  # noqa: E702
            b = (b - a) ^ _rot(a, 19); a = a + c  # noqa: E702
            c = (c - b) ^ _rot(b, 4); b = b + a  # noqa: E702
            a = a + words[3]
        else:
            a = a + words[0]
            if len(words) >= 2:
                b = b + words[1]
            if len(words) >= 3:
                c = c + words[2]
        return _final(a, b, c)


def _unit(h):
    return np.asarray(h).astype(F) / F(0xFFFFFFFF)  # Blender's (float)hash / (float)0xFFFFFFFF


def _grad(h, f):
    """Perlin's gradient for hash h at offsets f (a list of arrays, one per axis)."""
    n = len(f)
    if n == 1:
        h = h & 15
        return np.where(h & 8, -1, 1) * (1 + (h & 7)).astype(F) * f[0]
    if n == 2:
        h = h & 7
        u, v = np.where(h < 4, f[0], f[1]), 2 * np.where(h < 4, f[1], f[0])
        return np.where(h & 1, -u, u) + np.where(h & 2, -v, v)
    if n == 3:
        h = h & 15
        u = np.where(h < 8, f[0], f[1])
        v = np.where(h < 4, f[1], np.where((h == 12) | (h == 14), f[0], f[2]))
        return np.where(h & 1, -u, u) + np.where(h & 2, -v, v)
    h = h & 31
    u, v, s = np.where(h < 24, f[0], f[1]), np.where(h < 16, f[1], f[2]), np.where(h < 8, f[2], f[3])
    return np.where(h & 1, -u, u) + np.where(h & 2, -v, v) + np.where(h & 4, -s, s)


SCALES = {1: 0.2500, 2: 0.6616, 3: 0.9820, 4: 0.8344}  # Blender's per-dimension noise scales


def snoise(p):
    """Blender's signed Perlin noise of points p, shape (n, dims)."""
    p = np.asarray(p, F)
    p = (np.fmod(p, F(100000)) + np.where(np.abs(p) >= 1e6, F(0.5), F(0))).astype(F)
    cell = np.floor(p)
    f = (p - cell).astype(F)
    fade = f * f * f * (f * (f * 6 - 15) + 10)
    cell = cell.astype(np.int64)
    total = np.zeros(len(p), np.float64)
    dims = p.shape[1]
    for corner in np.ndindex(*(2,) * dims):
        h = _hash(*[(cell[:, k] + corner[k]) & 0xFFFFFFFF for k in range(dims)])
        g = _grad(h, [f[:, k] - corner[k] for k in range(dims)])
        w = np.prod([fade[:, k] if corner[k] else 1 - fade[:, k] for k in range(dims)], axis=0)
        total += w * g
    return (SCALES[dims] * total).astype(F)


def fbm(p, detail, rough, lac, normalize):
    s, amp, maxamp, total = F(1), F(1), F(0), np.zeros(len(p), F)
    for _ in range(int(detail) + 1):
        total += snoise(p * s) * amp
        maxamp += amp
        amp *= F(rough)
        s *= F(lac)
    rest = F(detail - np.floor(detail))
    if rest:
        total2 = total + snoise(p * s) * amp
        if normalize:
            return (1 - rest) * (0.5 * total / maxamp + 0.5) + rest * (0.5 * total2 / (maxamp + amp) + 0.5)
        return (1 - rest) * total + rest * total2
    return 0.5 * total / maxamp + 0.5 if normalize else total


def multifractal(p, detail, rough, lac):
    value, pwr = np.ones(len(p), F), F(1)
    for _ in range(int(detail) + 1):
        value *= pwr * snoise(p) + 1
        pwr *= F(rough)
        p = p * F(lac)
    rest = F(detail - np.floor(detail))
    if rest:
        value *= rest * pwr * snoise(p) + 1
    return value


def hetero_terrain(p, detail, rough, lac, offset):
    pwr = F(rough)
    value = F(offset) + snoise(p)
    p = p * F(lac)
    for _ in range(1, int(detail) + 1):
        value = value + (snoise(p) + F(offset)) * pwr * value
        pwr *= F(rough)
        p = p * F(lac)
    rest = F(detail - np.floor(detail))
    if rest:
        value = value + rest * ((snoise(p) + F(offset)) * pwr * value)
    return value


def hybrid_multifractal(p, detail, rough, lac, offset, gain):
    pwr, value, weight = F(1), np.zeros(len(p), F), np.ones(len(p), F)
    going = np.ones(len(p), bool)  # Blender's loop stops, per point, once the weight is <= 0.001
    for _ in range(int(detail) + 1):
        going &= weight > 0.001
        weight = np.where(going, np.minimum(weight, 1), weight)
        signal = (snoise(p) + F(offset)) * pwr
        value = np.where(going, value + weight * signal, value)
        weight = np.where(going, weight * F(gain) * signal, weight)
        pwr *= F(rough)
        p = p * F(lac)
    rest = F(detail - np.floor(detail))
    going &= weight > 0.001
    if rest:
        signal = (snoise(p) + F(offset)) * pwr
        value = np.where(going, value + rest * np.minimum(weight, 1) * signal, value)
    return value


def ridged_multifractal(p, detail, rough, lac, offset, gain):
    pwr = F(rough)
    signal = (F(offset) - np.abs(snoise(p))) ** 2
    value = signal
    for _ in range(1, int(detail) + 1):
        p = p * F(lac)
        weight = np.clip(signal * F(gain), 0, 1)
        signal = (F(offset) - np.abs(snoise(p))) ** 2 * weight
        value = value + signal * pwr
        pwr *= F(rough)
    return value


def fractal(kind, p, detail, rough, lac, offset, gain, normalize):
    if kind == "FBM":
        return fbm(p, detail, rough, lac, normalize)
    if kind == "MULTIFRACTAL":
        return multifractal(p, detail, rough, lac)
    if kind == "HETERO_TERRAIN":
        return hetero_terrain(p, detail, rough, lac, offset)
    if kind == "HYBRID_MULTIFRACTAL":
        return hybrid_multifractal(p, detail, rough, lac, offset, gain)
    return ridged_multifractal(p, detail, rough, lac, offset, gain)


def random_offset(seed, dims):
    """Blender's random_float_offset (1-D: a hash of the seed) .. random_float4_offset."""
    if dims == 1:
        return np.array([F(100) + _unit(_hash(F(seed).view(U))) * F(100)], F)
    return np.array([F(100) + _unit(_hash(F(seed).view(U), F(k).view(U))) * F(100) for k in range(dims)], F)


def noise_texture(vector, w, dims, kind, scale, detail, rough, lac, offset, gain, distortion, normalize):
    """(Fac, Color) of Blender's Noise Texture node at points `vector` (n, 3) and `w` (n,)."""
    detail, rough = min(max(detail, 0.0), 15.0), max(rough, 0.0)
    vector, w = np.asarray(vector, F) * F(scale), np.asarray(w, F) * F(scale)
    p = {1: w[:, None], 2: vector[:, :2], 3: vector, 4: np.column_stack([vector, w])}[dims].astype(F)
    if distortion:
        p = p + np.column_stack([snoise(p + random_offset(k, dims)) * F(distortion) for k in range(dims)])
    args = (detail, rough, lac, offset, gain, normalize)
    value = fractal(kind, p, *args)
    colour = np.column_stack([value, fractal(kind, p + random_offset(dims, dims), *args),
                              fractal(kind, p + random_offset(dims + 1, dims), *args)])
    return value, colour


def run_noise(vector, w, dims, kind, scale, detail, rough, lac, offset, gain, distortion, normalize, colour=True):
    """(Fac, Color) from the core's NOISE instruction over the points' object coordinates (the
    vector) and their generated x (W)."""
    b = nodes.Builder()
    values = dict(Scale=scale, Detail=detail, Roughness=rough, Lacunarity=lac, Distortion=distortion, W=0.0,
                  Offset=offset, Gain=gain)
    params = b.register(values[nodes.NOISE_PARAMS[0]])
    for name in nodes.NOISE_PARAMS[1:]:
        b.register(values[name])
    gen = b.global_("GENERATED")
    b.emit("COPY", params + nodes.NOISE_PARAMS.index("W"), gen, 1)
    fac, col = b.register(), b.register(width=3)
    b.emit("NOISE", fac, col, b.global_("OBJECT"), params, dims, nodes.NOISE_TYPES.index(kind),
           int(normalize) | 2 * int(colour))
    r = nodes.run(b.program(), len(vector), object=vector, generated=np.column_stack([w, np.zeros_like(w), np.zeros_like(w)]))
    return r[:, fac], r[:, col:col + 3]


POINTS = RNG.uniform(-3, 3, (300, 3)).astype(F)
W = RNG.uniform(-3, 3, 300).astype(F)


@pytest.mark.parametrize("dims", [1, 2, 3, 4])
@pytest.mark.parametrize("kind", nodes.NOISE_TYPES)
@pytest.mark.parametrize("detail", [0.0, 2.5, 3.0])
def test_noise_matches_blenders_definition(dims, kind, detail):
    # Settings off Blender's defaults, so that every input matters: a fractional detail
    # blends in a last octave (ridged: Blender reads only whole octaves).
    settings = dict(scale=1.7, detail=detail, rough=0.6, lac=2.1, offset=0.9, gain=1.4, distortion=0.0,
                    normalize=True)
    got, got_colour = run_noise(POINTS, W, dims, kind, **settings)
    want, want_colour = noise_texture(POINTS, W, dims, kind, **settings)
    tol = 2e-5 * max(1.0, float(np.abs(want).max()))
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=tol)
    np.testing.assert_allclose(got_colour, want_colour, rtol=1e-4, atol=tol)
    assert np.std(got) > 0.02  # a pattern, not a constant


@pytest.mark.parametrize("dims", [1, 2, 3, 4])
@pytest.mark.parametrize("kind", ["FBM", "HYBRID_MULTIFRACTAL"])
def test_distortion_and_normalize(dims, kind):
    settings = dict(scale=0.8, detail=1.5, rough=0.7, lac=1.9, offset=0.5, gain=2.0, distortion=0.7,
                    normalize=False)
    got, got_colour = run_noise(POINTS, W, dims, kind, **settings)
    want, want_colour = noise_texture(POINTS, W, dims, kind, **settings)
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=5e-5)
    np.testing.assert_allclose(got_colour, want_colour, rtol=1e-4, atol=5e-5)
    undistorted, _ = noise_texture(POINTS, W, dims, kind, **{**settings, "distortion": 0.0})
    assert np.abs(want - undistorted).mean() > 0.05  # the distortion is seen


def test_w_moves_the_4d_noise_and_is_ignored_in_3d():
    a3, _ = run_noise(POINTS, W, 3, "FBM", 2.0, 2.0, 0.5, 2.0, 0.0, 1.0, 0.0, True)
    b3, _ = run_noise(POINTS, W + 0.37, 3, "FBM", 2.0, 2.0, 0.5, 2.0, 0.0, 1.0, 0.0, True)
    np.testing.assert_array_equal(a3, b3)
    a4, _ = run_noise(POINTS, W, 4, "FBM", 2.0, 2.0, 0.5, 2.0, 0.0, 1.0, 0.0, True)
    b4, _ = run_noise(POINTS, W + 0.37, 4, "FBM", 2.0, 2.0, 0.5, 2.0, 0.0, 1.0, 0.0, True)
    assert np.abs(a4 - b4).mean() > 0.02


def test_types_differ_and_bounds_hold():
    """Each type is its own pattern (a wrong type would not pass the tests above), detail is
    held within 0..15 and roughness at 0 or more, as Blender holds them."""
    base = dict(scale=1.3, rough=0.6, lac=2.0, offset=1.0, gain=2.0, distortion=0.0, normalize=True)
    out = {kind: run_noise(POINTS, W, 3, kind, detail=3.0, **base)[0] for kind in nodes.NOISE_TYPES}
    for a in nodes.NOISE_TYPES:
        for b in nodes.NOISE_TYPES:
            if a < b:
                assert np.abs(out[a] - out[b]).max() > 0.1, (a, b)
    for dims in (1, 4):
        high, _ = run_noise(POINTS, W, dims, "MULTIFRACTAL", detail=40.0, **base)
        fifteen, _ = run_noise(POINTS, W, dims, "MULTIFRACTAL", detail=15.0, **base)
        np.testing.assert_array_equal(high, fifteen)
        negative, _ = run_noise(POINTS, W, dims, "FBM", detail=2.0, **{**base, "rough": -0.5})
        zero, _ = run_noise(POINTS, W, dims, "FBM", detail=2.0, **{**base, "rough": 0.0})
        np.testing.assert_array_equal(negative, zero)


def test_the_colour_is_not_computed_when_unread():
    fac, colour = run_noise(POINTS, W, 4, "RIDGED_MULTIFRACTAL", 1.0, 2.0, 0.5, 2.0, 1.0, 2.0, 0.0, True, colour=False)
    with_colour, _ = run_noise(POINTS, W, 4, "RIDGED_MULTIFRACTAL", 1.0, 2.0, 0.5, 2.0, 1.0, 2.0, 0.0, True)
    np.testing.assert_array_equal(fac, with_colour)
    assert not colour.any()


def test_non_finite_points_give_zero_noise():
    bad = np.array([[np.inf, 0, 0], [np.nan, 1, 2], [1e30, -1e30, 3]], F)
    for dims in (1, 2, 3, 4):
        fac, _ = run_noise(bad, bad[:, 0], dims, "FBM", 1.0, 2.0, 0.5, 2.0, 0.0, 1.0, 0.5, False)
        assert np.isfinite(fac).all()


@pytest.mark.parametrize("dims", [0, 5, -1])
def test_a_noise_row_outside_one_to_four_dimensions_is_refused(dims):
    """The NOISE instruction keeps the dimension count itself, 1-4 (the compiler's encoding;
    Voronoi keeps it less one): a hand-built program with any other count is refused,
    naming its row, not run as 3-D noise (0 did before) or read past the block."""
    b = nodes.Builder()
    params = b.register((1.0, 2.0, 0.5, 2.0, 0.0, 0.0, 0.0, 1.0), len(nodes.NOISE_PARAMS))
    vector = b.global_("OBJECT")  # row 0
    fac, col = b.register(), b.register(width=3)
    b.emit("NOISE", fac, col, vector, params, dims, 0, 0)  # row 1
    with pytest.raises(ValueError, match=r"node instruction 1: (noise dimensions must be 1 to 4|value out of range)"):
        nodes.run(b.program(), 2, object=POINTS[:2])
