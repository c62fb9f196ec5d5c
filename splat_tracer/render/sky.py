"""Blender's Sky Texture evaluated from its definition, in numpy: Single and Multiple Scattering
(`Sky`, below) and the older Preetham and Hosek-Wilkie models (`LegacySky`, at the end).

Cycles renders the Sky Texture from a table of the sky's radiance (CIE XYZ) over the view
direction's azimuth relative to the sun and its elevation, computed once per sun elevation and
atmosphere, looked up with linear interpolation, converted to scene linear and clamped at 0;
plus the sun's disc, its radiance interpolated between the disc's lowest and highest points
and darkened towards its limb. This module computes the same tables from the same physical
model (Blender's intern/sky read as a description, not copied) so that a world bake gives the
sky Cycles gives:

- Multiple Scattering (Blender 5's default; Fernando Garcia Linan's spectral model): the
  single scattering of sunlight by molecules (Rayleigh) and aerosols (Henyey-Greenstein)
  along the view ray up to the ground or the top of the atmosphere, ozone absorption, the
  transmittance to the sun from a table over (sun zenith cosine, altitude), and a fitted
  multiple-scattering term (light scattered more than once, and by the ground); evaluated at
  four wavelengths whose combination into XYZ is fitted to the full spectrum.
- Single Scattering (Nishita's): the same single scattering with exponential density
  profiles, at 21 wavelengths from 380 to 780 nm weighted by the CIE 1931 colour matching
  functions; below the horizon the horizon's colour fading to black.

Units follow Cycles': the result is a radiance whose scale is the models' (W m^-2 sr^-1
integrated against the matching functions), so a sky at sun elevation 30 degrees lights an
upward-facing white surface with an irradiance of some 30 in scene linear units.
"""
from __future__ import annotations

import math

import numpy as np

# Cycles' table of the sky (intern/cycles/scene/image_sky.cpp): azimuth x elevation texels.
TABLE_WIDTH, TABLE_HEIGHT = 512, 256

# CIE XYZ (D65-adapted, Blender's cie_xyz_d65_interchange role) to scene linear Rec.709: the
# BT.709 primaries with a D65 white, as the OCIO configuration bundled with Blender defines it.
XYZ_TO_REC709 = np.array([[3.2409699, -1.5373832, -0.4986108],
                          [-0.9692436, 1.8759675, 0.0415551],
                          [0.0556301, -0.2039770, 1.0569715]])

# Cycles' sun disc: radiance falls to 1 - LIMB_DARKENING at the limb, following
# 1 - u (1 - sqrt(1 - (r/R)^2)) (a linear limb-darkening law in the cosine of the angle
# on the sun's surface); u = 0.6 is about the sun's in visible light.
LIMB_DARKENING = 0.6
# The mean of that profile over the disc's area: 1 - u (1 - 2/3).
LIMB_MEAN = 1.0 - LIMB_DARKENING / 3.0


# ------------------------------------------------------------------------------------------
# Multiple Scattering (distances in km).

MS_EARTH_RADIUS = 6371.0            # mean radius of the Earth (km)
MS_ATMOSPHERE_THICKNESS = 100.0     # height of the top of the atmosphere, the Karman line (km)
MS_GROUND_ALBEDO = 0.3              # the ground's diffuse reflectance, for light it sends back up
MS_AEROSOL_G = 0.8                  # aerosols' Henyey-Greenstein anisotropy (strongly forward)
MS_STEPS = 64                       # midpoint steps along a view ray and along a ray to the sun
MS_LUT = (256, 64)                  # the transmittance table: sun zenith cosine x altitude
# The model's four wavelengths: 630, 560, 490 and 430 nm.
# Solar spectral irradiance at the top of the atmosphere at those (W m^-2 nm^-1).
MS_SUN_IRRADIANCE = np.array([1.679, 1.828, 1.986, 1.307])
# Molecular (Rayleigh) scattering coefficient at sea level (km^-1), ~ lambda^-4.
MS_MOLECULAR_SCATTERING = np.array([6.605e-3, 1.067e-2, 1.842e-2, 3.156e-2])
# Ozone's absorption cross-section (cm^2 per molecule): the Chappuis band, strongest in the
# orange, gives the blue of the sky at sunset.
MS_OZONE_CROSS_SECTION = np.array([3.472e-25, 3.914e-25, 1.349e-25, 11.03e-27])
MS_OZONE_DOBSON = 334.5             # the ozone column, mean of monthly means (Dobson units)
# Urban aerosols: absorption and scattering cross-sections (cm^2 per particle), their number
# density at the ground and far above it (per km^3 units of the fit), their scale height (km).
MS_AEROSOL_ABSORPTION = np.array([2.8722e-24, 4.6168e-24, 7.9706e-24, 1.3578e-23])
MS_AEROSOL_SCATTERING = np.array([1.5908e-22, 1.7711e-22, 2.0942e-22, 2.4033e-22])
MS_AEROSOL_BASE_DENSITY = 1.3681e20
MS_AEROSOL_BACKGROUND_DENSITY = 2e6
MS_AEROSOL_SCALE_HEIGHT = 0.73
# The four samples' weights into CIE XYZ: the colour matching functions integrated against the
# spectrum the four samples stand for (the model's fit; one row per wavelength).
MS_SPECTRAL_TO_XYZ = np.array([[53.386917738564668, 22.981337506691025, 0.0],
                               [43.904844466369358, 71.347795700053394, 0.10250686796574131],
                               [1.6137278251608962, 18.422960591455485, 31.742921188390806],
                               [20.762668673810577, 2.3614213523314369, 110.48009643252140]])
# Light scattered more than once, as the model fits it from a path tracer: a blue-ish
# isotropic source of 2 % of the sun's, fading as the sun sets (a logistic in its cosine).
MS_MULTIPLE_COLOUR = 0.02 * np.array([0.217, 0.347, 0.594, 1.0])
MS_MULTIPLE_SLOPE, MS_MULTIPLE_OFFSET = 17.92, 5.0


def _sphere_hit(origin: np.ndarray, direction: np.ndarray, radius: float) -> np.ndarray:
    """Distance along unit `direction` from `origin` (..., 3) to a sphere about the Earth's
    centre: the far side from inside, the near side from outside, -1 when missed or behind."""
    b = np.einsum("...i,...i->...", origin, direction)
    c = np.einsum("...i,...i->...", origin, origin) - radius * radius
    d = b * b - c
    root = np.sqrt(np.maximum(d, 0.0))
    t = np.where(d >= b * b, -b + root, -b - root)
    return np.where((d < 0) | ((c > 0) & (b > 0)), -1.0, t)


def _sun_direction(cos_zenith):
    """The sun in the tables' frame: azimuth pi (the x < 0 side), zenith cosine given."""
    cos_zenith = np.asarray(cos_zenith, np.float64)
    return np.stack([-np.sqrt(np.maximum(1.0 - cos_zenith ** 2, 0.0)), 0.0 * cos_zenith, cos_zenith], -1)


class MultipleScattering:
    """One atmosphere of the Multiple Scattering model (densities relative to urban air)."""

    def __init__(self, air: float = 1.0, aerosol: float = 1.0, ozone: float = 1.0):
        self.air, self.aerosol, self.ozone = float(air), float(aerosol), float(ozone)
        self._lut_values = None

    @property
    def lut(self) -> np.ndarray:
        """The transmittance table (ny, nx, 4) over (sun zenith cosine in [-1, 1], altitude)."""
        if self._lut_values is None:
            nx, ny = MS_LUT
            u, v = np.meshgrid(np.arange(nx) / (nx - 1), np.arange(ny) / (ny - 1))
            self._lut_values = self.transmittance(2.0 * u - 1.0, v)
        return self._lut_values

    def extinction_and_scattering(self, h: np.ndarray):
        """(extinction, molecular scattering, aerosol scattering), each (..., 4) km^-1, at
        heights h (km) above the ground."""
        h = np.asarray(h, np.float64)[..., None]
        molecular = MS_MOLECULAR_SCATTERING * np.exp(-0.07771971 * h ** 1.16364243) * self.air  # fitted profile
        log_h = np.log(np.maximum(h, 1e-4))
        # Ozone: a log-normal profile in height, peaking at ~25 km (e^3.22), in molecules.
        ozone_density = 3.78547397e20 * np.exp(-(log_h - 3.22261) ** 2 * 5.55555555 - log_h)
        ozone = MS_OZONE_CROSS_SECTION * MS_OZONE_DOBSON * ozone_density * self.ozone
        aerosols = MS_AEROSOL_BASE_DENSITY * (np.exp(-h / MS_AEROSOL_SCALE_HEIGHT)
                                              + MS_AEROSOL_BACKGROUND_DENSITY / MS_AEROSOL_BASE_DENSITY) * self.aerosol
        aerosol_scattering = MS_AEROSOL_SCATTERING * aerosols
        extinction = molecular + ozone + aerosol_scattering + MS_AEROSOL_ABSORPTION * aerosols
        return extinction, molecular, aerosol_scattering

    def transmittance(self, cos_zenith, normalized_altitude) -> np.ndarray:
        """Transmittance (..., 4) from a height (a fraction of the atmosphere's) to the top of
        the atmosphere towards a sun of the given zenith cosine (through the Earth when below
        the horizon, as the model has it: heights are clamped at the ground)."""
        cos_zenith, normalized_altitude = np.broadcast_arrays(np.asarray(cos_zenith, np.float64),
                                                              np.asarray(normalized_altitude, np.float64))
        sun = _sun_direction(cos_zenith)
        r0 = MS_EARTH_RADIUS + MS_ATMOSPHERE_THICKNESS * normalized_altitude
        origin = np.stack([0 * r0, 0 * r0, r0], -1)
        length = _sphere_hit(origin, sun, MS_EARTH_RADIUS + MS_ATMOSPHERE_THICKNESS)
        dt = length / MS_STEPS
        depth = np.zeros(cos_zenith.shape + (4,))
        for i in range(MS_STEPS):
            p = origin + sun * ((i + 0.5) * dt)[..., None]
            h = np.maximum(np.linalg.norm(p, axis=-1) - MS_EARTH_RADIUS, 0.0)
            depth += self.extinction_and_scattering(h)[0] * dt[..., None]
        return np.exp(-depth)

    def _lut(self, cos_zenith, normalized_altitude) -> np.ndarray:
        """The transmittance table, bilinear (clamped at its edges)."""
        nx, ny = MS_LUT
        flat = self.lut.reshape(-1, 4)
        x = np.clip(cos_zenith * 0.5 + 0.5, 0.0, 1.0) * (nx - 1)
        y = np.clip(normalized_altitude, 0.0, 1.0) * (ny - 1)
        x1, y1 = x.astype(np.int64), y.astype(np.int64)
        dx, dy = (x1 < nx - 1).astype(np.int64), (y1 < ny - 1).astype(np.int64) * nx
        fx, fy = (x - x1)[..., None], (y - y1)[..., None]
        i = y1 * nx + x1
        bottom = flat[i] + (flat[i + dx] - flat[i]) * fx
        top = flat[i + dy] + (flat[i + dy + dx] - flat[i + dy]) * fx
        return bottom + (top - bottom) * fy

    def _multiple(self, cos_zenith, normalized_altitude, distance) -> np.ndarray:
        """Light reaching a point by more than one bounce, per unit scattering: the ground's
        reflection of the sun (a Lambertian ground of MS_GROUND_ALBEDO seen under the solid
        angle the Earth subtends, scattered isotropically) plus the fitted atmospheric term."""
        nx, ny = MS_LUT
        omega = 2.0 * math.pi * (1.0 - np.sqrt(np.maximum(1.0 - (MS_EARTH_RADIUS / distance) ** 2, 0.0)))
        # The table at the ground (its first row) and towards the zenith (its last column).
        ground_row, zenith_column = self.lut[0], self.lut[:, -1]
        to_ground = np.stack([np.interp(np.clip(cos_zenith * 0.5 + 0.5, 0, 1) * (nx - 1), np.arange(nx),
                                        ground_row[:, c]) for c in range(4)], -1)
        at = np.clip(normalized_altitude, 0, 1) * (ny - 1)
        ground_to_sample = zenith_column[0] / np.stack([np.interp(at, np.arange(ny), zenith_column[:, c])
                                                        for c in range(4)], -1)
        ground = (1.0 / (4.0 * math.pi)) * (omega * cos_zenith)[..., None] * (MS_GROUND_ALBEDO / math.pi) \
            * to_ground * ground_to_sample
        fit = MS_MULTIPLE_COLOUR / (1.0 + MS_MULTIPLE_OFFSET * np.exp(-MS_MULTIPLE_SLOPE * cos_zenith))[..., None]
        return fit + ground

    def radiance_xyz(self, directions: np.ndarray, sun_elevation: float, altitude_m: float) -> np.ndarray:
        """The sky's in-scattered radiance (N, 3 XYZ) along unit `directions` (N, 3) in the
        tables' frame (sun at azimuth pi), from `altitude_m` metres above the ground."""
        altitude = min(max(float(altitude_m), 1.0), 99999.0) / 1000.0
        sun = _sun_direction(math.cos(math.pi / 2 - sun_elevation))
        origin = np.array([0.0, 0.0, MS_EARTH_RADIUS + altitude])
        d = np.asarray(directions, np.float64)
        o = np.broadcast_to(origin, d.shape)
        to_top = _sphere_hit(o, d, MS_EARTH_RADIUS + MS_ATMOSPHERE_THICKNESS)
        to_ground = _sphere_hit(o, d, MS_EARTH_RADIUS)
        length = np.where(to_ground < 0.0, to_top, to_ground)
        cos_theta = -(d @ sun)  # the angle between the light's travel (from the sun) and the ray back
        molecular_phase = 3.0 / (16.0 * math.pi) * (1.0 + cos_theta ** 2)
        g = MS_AEROSOL_G
        den = 1.0 + g * g + 2.0 * g * cos_theta
        aerosol_phase = (1.0 - g * g) / (4.0 * math.pi * den * np.sqrt(den))
        dt = length / MS_STEPS
        radiance = np.zeros(d.shape[:-1] + (4,))
        transmittance = np.ones_like(radiance)
        for i in range(MS_STEPS):
            p = o + d * ((i + 0.5) * dt)[..., None]
            r = np.linalg.norm(p, axis=-1)
            h = np.maximum(r - MS_EARTH_RADIUS, 0.0)
            nh = h / MS_ATMOSPHERE_THICKNESS
            cos_sun = (p @ sun) / r
            extinction, molecular, aerosol = self.extinction_and_scattering(h)
            to_sun = self._lut(cos_sun, nh)
            ms = self._multiple(cos_sun, nh, r)
            source = MS_SUN_IRRADIANCE * (molecular * (molecular_phase[..., None] * to_sun + ms)
                                          + aerosol * (aerosol_phase[..., None] * to_sun + ms))
            step = np.exp(-dt[..., None] * extinction)
            # The source integrated exactly over the step against its own extinction
            # (Hillaire 2016, energy-conserving).
            radiance += transmittance * (source - source * step) / np.maximum(extinction, 1e-7)
            transmittance *= step
        return radiance @ MS_SPECTRAL_TO_XYZ

    def sun_xyz(self, elevation: float, solid_angle: float, altitude_m: float) -> np.ndarray:
        """The sun disc's radiance (XYZ) seen at `elevation`: the sun's irradiance through the
        atmosphere spread over the disc's solid angle."""
        altitude = min(max(float(altitude_m), 1.0), 99999.0) / 1000.0
        t = self.transmittance(math.sin(elevation), altitude / MS_ATMOSPHERE_THICKNESS)
        return (MS_SUN_IRRADIANCE * t / solid_angle) @ MS_SPECTRAL_TO_XYZ


# ------------------------------------------------------------------------------------------
# Single Scattering (Nishita's; distances in m).

SS_EARTH_RADIUS = 6360e3            # radius of the Earth (m)
SS_ATMOSPHERE_RADIUS = 6420e3       # radius of the top of the atmosphere (m)
SS_RAYLEIGH_SCALE = 8e3             # molecules' scale height: density ~ exp(-h / 8 km)
SS_MIE_SCALE = 1.2e3                # aerosols' scale height (m)
SS_MIE_COEFF = 2e-5                 # aerosols' scattering coefficient at sea level (m^-1)
SS_MIE_EXTINCTION = 1.11            # aerosols' extinction / scattering (an albedo of 0.9)
SS_MIE_G = 0.76                     # aerosols' anisotropy (Cornette-Shanks phase function)
SS_OZONE_PEAK, SS_OZONE_WIDTH = 25e3, 15e3  # ozone: a tent profile from 10 to 40 km (m)
SS_STEPS = 32                       # midpoint steps along a view ray
SS_LAMBDA = np.linspace(380.0, 780.0, 21)   # sampled wavelengths (nm), 20 nm apart
SS_STEP_LAMBDA = 20.0
# Solar spectral irradiance at the top of the atmosphere (W m^-2 nm^-1) at SS_LAMBDA.
SS_IRRADIANCE = np.array([
    1.45756829855593, 1.56596305559738, 1.65148449067670, 1.71496242737209, 1.75797983805021,
    1.78256407885925, 1.79095108475839, 1.78541550133411, 1.76815554864307, 1.74122069647250,
    1.70647127164944, 1.66556087452740, 1.61993437242452, 1.57083597368892, 1.51932335059305,
    1.46628494965214, 1.41245852740172, 1.35844961970384, 1.30474913844739, 1.25174963272611,
    1.19975998755421])
# Rayleigh scattering coefficient at sea level (m^-1) at SS_LAMBDA (~ lambda^-4).
SS_RAYLEIGH = np.array([
    5.424820087636473e-05, 4.418549866505454e-05, 3.635151910165377e-05, 3.017929012024763e-05,
    2.526320226989157e-05, 2.130859310621843e-05, 1.809838025320633e-05, 1.547057129129042e-05,
    1.330284977336850e-05, 1.150184784075764e-05, 9.99557429990163e-06, 8.72799973630707e-06,
    7.65513700977967e-06, 6.74217203751443e-06, 5.96134125832052e-06, 5.29034598065810e-06,
    4.71115687557433e-06, 4.20910481110487e-06, 3.77218381260133e-06, 3.39051255477280e-06,
    3.05591531679811e-06])
# Ozone absorption coefficient at its peak density (m^-1) at SS_LAMBDA (Chappuis band).
SS_OZONE = np.array([
    3.25126849861e-09, 5.85395365047e-09, 1.977191155085e-08, 7.309568762914e-08, 2.0084561514287e-07,
    4.0383958096161e-07, 6.3551335912363e-07, 9.6707041180970e-07, 1.54797400424410e-06, 2.09038647223331e-06,
    2.46128056164565e-06, 2.73551299461512e-06, 2.15125863128643e-06, 1.59051840791988e-06, 1.12356197979857e-06,
    7.3527551487574e-07, 4.6450130357806e-07, 3.3096079921048e-07, 2.2512612292678e-07, 1.4879129266490e-07,
    1.6828623364192e-07])
# CIE 1931 2-degree colour matching functions (x, y, z) at SS_LAMBDA.
SS_CMF = np.array([
    [0.001368, 0.000039, 0.006450001], [0.01431, 0.000396, 0.06785001], [0.13438, 0.004, 0.6456],
    [0.34828, 0.023, 1.74706], [0.2908, 0.06, 1.6692], [0.09564, 0.13902, 0.8129501],
    [0.0049, 0.323, 0.272], [0.06327, 0.71, 0.07824999], [0.2904, 0.954, 0.0203],
    [0.5945, 0.995, 0.0039], [0.9163, 0.87, 0.001650001], [1.0622, 0.631, 0.0008],
    [0.8544499, 0.381, 0.00019], [0.4479, 0.175, 0.00002], [0.1649, 0.061, 0.0],
    [0.04677, 0.017, 0.0], [0.01135916, 0.004102, 0.0], [0.002899327, 0.001047, 0.0],
    [0.0006900786, 0.0002492, 0.0], [0.0001661505, 0.00006, 0.0], [0.00004150994, 0.00001499, 0.0]])


def _laguerre_nodes(n: int = 8, end: float = 25.0):
    """Gauss-Laguerre quadrature for an optical depth along a ray to the top of the atmosphere:
    the density falls about exponentially along it, so n nodes of the rule for f(x) e^-x
    (their weights times e^x), the ray scaled so that x = `end` is its end."""
    x, w = np.polynomial.laguerre.laggauss(n)
    return x / end, w * np.exp(x) / end


SS_NODES, SS_WEIGHTS = _laguerre_nodes()


def _ss_densities(height: np.ndarray) -> np.ndarray:
    """(..., 3): relative densities of molecules, aerosols and ozone at height (m)."""
    return np.stack([np.exp(-height / SS_RAYLEIGH_SCALE), np.exp(-height / SS_MIE_SCALE),
                     np.maximum(0.0, 1.0 - np.abs(height - SS_OZONE_PEAK) / SS_OZONE_WIDTH)], -1)


def _ss_optical_depth(origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(..., 3) optical depth factors (molecules, aerosols, ozone; m) to the atmosphere's top."""
    length = _sphere_hit(origin, direction, SS_ATMOSPHERE_RADIUS)
    depth = 0.0
    for x, w in zip(SS_NODES, SS_WEIGHTS):
        p = origin + direction * (x * length)[..., None]
        depth = depth + _ss_densities(np.linalg.norm(p, axis=-1) - SS_EARTH_RADIUS) * w
    return depth * length[..., None]


class SingleScattering:
    def __init__(self, air: float = 1.0, aerosol: float = 1.0, ozone: float = 1.0):
        self.scale = np.array([air, aerosol, ozone], np.float64)
        # Per wavelength: extinction per unit optical depth of each constituent (21, 3).
        self.extinction = np.stack([SS_RAYLEIGH, np.full(21, SS_MIE_EXTINCTION * SS_MIE_COEFF), SS_OZONE], -1)

    def radiance_xyz(self, directions: np.ndarray, sun_elevation: float, altitude_m: float) -> np.ndarray:
        """In-scattered radiance (N, 3 XYZ) along unit `directions` in the tables' frame (sun at
        azimuth 0 here, as Nishita's table has it)."""
        altitude = min(max(float(altitude_m), 1.0), 59999.0)
        sun = np.array([math.cos(sun_elevation), 0.0, math.sin(sun_elevation)])
        d = np.asarray(directions, np.float64)
        o = np.broadcast_to(np.array([0.0, 0.0, SS_EARTH_RADIUS + altitude]), d.shape)
        seg = _sphere_hit(o, d, SS_ATMOSPHERE_RADIUS) / SS_STEPS
        mu = d @ sun
        g2 = SS_MIE_G ** 2
        rayleigh_phase = 3.0 / (16.0 * math.pi) * (1.0 + mu ** 2)
        mie_phase = 3.0 * (1.0 - g2) * (1.0 + mu ** 2) / (
            8.0 * math.pi * (2.0 + g2) * (1.0 + g2 - 2.0 * SS_MIE_G * mu) ** 1.5)
        depth = np.zeros(d.shape[:-1] + (3,))
        spectrum = np.zeros(d.shape[:-1] + (21,))
        for i in range(SS_STEPS):
            p = o + d * ((i + 0.5) * seg)[..., None]
            density = self.scale * _ss_densities(np.linalg.norm(p, axis=-1) - SS_EARTH_RADIUS)
            depth += seg[..., None] * density
            # The sun hidden by the Earth: its ray from p meets the ground.
            if sun[2] < 0.0:
                b = 2.0 * (p @ sun)
                lit = (b * b - 4.0 * (np.einsum("...i,...i->...", p, p) - SS_EARTH_RADIUS ** 2)) < 0.0
            else:
                lit = np.ones(d.shape[:-1], bool)
            light = self.scale * _ss_optical_depth(p, np.broadcast_to(sun, p.shape))
            attenuation = np.exp(-((depth + light) @ self.extinction.T))  # (..., 21)
            scattering = (density[..., :1] * SS_RAYLEIGH * rayleigh_phase[..., None]
                          + density[..., 1:2] * SS_MIE_COEFF * mie_phase[..., None])
            spectrum += np.where(lit[..., None], attenuation * scattering * SS_IRRADIANCE * seg[..., None], 0.0)
        return spectrum @ SS_CMF * SS_STEP_LAMBDA

    def sun_xyz(self, elevation: float, solid_angle: float, altitude_m: float) -> np.ndarray:
        """The sun disc's radiance (XYZ) seen at `elevation` (clamped at the horizon): the
        sun's irradiance through molecules and aerosols (not ozone, as Cycles has it)."""
        altitude = min(max(float(altitude_m), 1.0), 59999.0)
        elevation = max(elevation, 0.0)
        depth = _ss_optical_depth(np.array([0.0, 0.0, SS_EARTH_RADIUS + altitude]),
                                  np.array([math.cos(elevation), 0.0, math.sin(elevation)]))
        tau = SS_RAYLEIGH * depth[0] * self.scale[0] + SS_MIE_EXTINCTION * SS_MIE_COEFF * depth[1] * self.scale[1]
        return (SS_IRRADIANCE * np.exp(-tau) / solid_angle) @ SS_CMF * SS_STEP_LAMBDA


# ------------------------------------------------------------------------------------------
# The node as Cycles renders it.

def earth_dip(altitude_m: float) -> float:
    """How far below the horizontal the Earth's edge is seen from `altitude_m` (radians): the
    sun disc is drawn only above it."""
    return math.pi / 2 - math.asin(MS_EARTH_RADIUS / (MS_EARTH_RADIUS + float(altitude_m) / 1000.0))


def _table(multiple: bool, sun_elevation: float, altitude: float, air: float, aerosol: float,
           ozone: float) -> np.ndarray:
    """Cycles' sky table (TABLE_HEIGHT, TABLE_WIDTH, 3 XYZ), the sun at its middle column."""
    w, h = TABLE_WIDTH, TABLE_HEIGHT
    half = w // 2
    if multiple:
        # Texel centres; the elevation's square root is linear in rows (more rows at the horizon).
        az = 2.0 * math.pi * (np.arange(half) + 0.5) / w
        l = 2.0 * (np.arange(h) + 0.5) / h - 1.0
        elev = np.sign(l) * l * l * (math.pi / 2)
        model = MultipleScattering(air, aerosol, ozone)
        rows = range(h)
    else:
        # Nishita's table: the upper half from the model, rows at latitude (y / (h/2) - 1)^2
        # (the horizon at row h/2), the sun at longitude 0 between columns w/2 - 1 and w/2;
        # the lower half below.
        az = 2.0 * math.pi * np.arange(half) / w - math.pi
        elev = (math.pi / 2) * (np.arange(h) / (h // 2) - 1.0) ** 2
        model = SingleScattering(air, aerosol, ozone)
        rows = range(h // 2, h)
    table = np.zeros((h, w, 3))
    rows = np.array(list(rows))
    e, a = np.meshgrid(elev[rows], az, indexing="ij")
    dirs = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1)
    xyz = model.radiance_xyz(dirs.reshape(-1, 3), sun_elevation, altitude).reshape(len(rows), half, 3)
    table[rows, :half] = xyz
    table[rows, half:] = xyz[:, ::-1]
    if not multiple:
        # Below the horizon Nishita's sky has no ground: the horizon's row faded to black by
        # (1 - 2.5 sin(depth))^3, black from 0.4 (24 degrees) down -- a look, not physics.
        depth = np.sin(elev[: h // 2])
        fade = np.where(depth < 0.4, (1.0 - 2.5 * depth) ** 3, 0.0)
        table[: h // 2] = table[h // 2][None] * fade[:, None, None]
    return table


def _lookup(table: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Linear interpolation between texel centres, clamped at the edges (Cycles' Extend)."""
    h, w = table.shape[:2]
    fx, fy = u * w - 0.5, v * h - 0.5
    x0, y0 = np.floor(fx), np.floor(fy)
    tx, ty = (fx - x0)[..., None], (fy - y0)[..., None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    x1, y1 = np.clip(x0 + 1, 0, w - 1), np.clip(y0 + 1, 0, h - 1)
    x0, y0 = np.clip(x0, 0, w - 1), np.clip(y0, 0, h - 1)
    return ((table[y0, x0] * (1 - tx) + table[y0, x1] * tx) * (1 - ty)
            + (table[y1, x0] * (1 - tx) + table[y1, x1] * tx) * ty)


def xyz_to_rgb(xyz: np.ndarray) -> np.ndarray:
    """XYZ to scene linear Rec.709, negative components clamped to 0 (as Cycles does)."""
    return np.maximum(xyz @ XYZ_TO_REC709.T, 0.0)


class Sky:
    """The Sky Texture of given settings (radians, metres, densities relative to Blender's
    defaults). `directions` are Blender world directions; the sun is at
    (sin(rotation) cos(elevation), cos(rotation) cos(elevation), sin(elevation))."""

    def __init__(self, multiple: bool = True, sun_elevation: float = math.radians(15.0), sun_rotation: float = 0.0,
                 altitude: float = 100.0, air: float = 1.0, aerosol: float = 1.0, ozone: float = 1.0,
                 sun_disc: bool = True, sun_size: float = math.radians(0.545), sun_intensity: float = 1.0):
        # Cycles' wrapping of the sun's position: an elevation past the zenith turns the sun round.
        e = math.fmod(float(sun_elevation), 2 * math.pi)
        if abs(e) >= math.pi:
            e -= math.copysign(2 * math.pi, e)
        r = float(sun_rotation)
        if e >= math.pi / 2 or e <= -math.pi / 2:
            e, r = math.copysign(math.pi, e) - e, r + math.pi
        self.multiple, self.elevation, self.rotation = multiple, e, r
        self.altitude, self.sun_disc = float(altitude), bool(sun_disc)
        self.size, self.intensity = max(float(sun_size), 0.0), float(sun_intensity)
        self._atmosphere = (air, aerosol, ozone)
        self._table = None  # computed when the sky is first looked up: the sun alone needs none
        model = MultipleScattering(air, aerosol, ozone) if multiple else SingleScattering(air, aerosol, ozone)
        half = self.size / 2
        solid = 2 * math.pi * (1 - math.cos(half)) if half > 0 else 1.0
        self.sun_bottom = xyz_to_rgb(model.sun_xyz(e - half, solid, altitude))
        self.sun_top = xyz_to_rgb(model.sun_xyz(e + half, solid, altitude))
        self.sun_solid_angle = solid

    @property
    def table(self) -> np.ndarray:
        if self._table is None:
            self._table = _table(self.multiple, self.elevation, self.altitude, *self._atmosphere)
        return self._table

    @property
    def sun_direction(self) -> np.ndarray:
        e, r = self.elevation, self.rotation
        return np.array([math.sin(r) * math.cos(e), math.cos(r) * math.cos(e), math.sin(e)])

    def sky(self, directions: np.ndarray) -> np.ndarray:
        """The sky without the sun's disc (N, 3 scene linear) along unit `directions`."""
        d = np.asarray(directions, np.float64)
        phi = np.arctan2(d[:, 1], d[:, 0])
        sun = self.sun_direction
        # The table's middle column is the sun's azimuth (the table is symmetric about it).
        u = np.remainder(0.5 + (phi - math.atan2(sun[1], sun[0])) / (2 * math.pi), 1.0)
        elev = np.arcsin(np.clip(d[:, 2], -1.0, 1.0))
        v = 0.5 + 0.5 * np.sign(elev) * np.sqrt(np.abs(elev) / (math.pi / 2))
        return xyz_to_rgb(_lookup(self.table, u, v))

    def sun_radiance(self, directions: np.ndarray) -> np.ndarray:
        """The sun disc's radiance (N, 3) along `directions` (0 outside it), limb-darkened."""
        d = np.asarray(directions, np.float64)
        out = np.zeros(d.shape)
        if not self.sun_disc or self.size <= 0:
            return out
        half = self.size / 2
        angle = np.arccos(np.clip(d @ self.sun_direction, -1.0, 1.0))
        elev = np.arcsin(np.clip(d[:, 2], -1.0, 1.0))
        inside = (angle < half) & (elev > -earth_dip(self.altitude))
        y = ((elev - self.elevation) / self.size + 0.5)[:, None]
        limb = 1.0 - LIMB_DARKENING * (1.0 - np.sqrt(np.maximum(1.0 - (angle / half) ** 2, 0.0)))
        rgb = (self.sun_bottom + (self.sun_top - self.sun_bottom) * y) * limb[:, None]
        out[inside] = rgb[inside] * self.intensity
        return out

    def sun_power(self) -> np.ndarray:
        """The disc's radiance integrated over its solid angle (an irradiance on a surface
        facing it), RGB: the centre's radiance (the disc's mean, radiance being linear in
        elevation across it) times the limb profile's mean. 0 when no disc or once the whole
        disc is below the Earth's edge."""
        if not self.sun_disc or self.size <= 0 or self.elevation + self.size / 2 <= -earth_dip(self.altitude):
            return np.zeros(3)
        if not self.multiple and self.elevation + self.size / 2 <= 0:
            return np.zeros(3)
        return 0.5 * (self.sun_bottom + self.sun_top) * LIMB_MEAN * self.sun_solid_angle * self.intensity


# ------------------------------------------------------------------------------------------
# Blender's legacy models: analytic functions of the view direction's zenith angle theta and
# its angle gamma to the sun, no table and no sun disc; below the horizon the horizon's theta.

# Cycles clamps the view's zenith angle just short of the horizon (the models' functions divide
# by cos(theta)): the ground repeats the horizon's colour, still varying with gamma.
LEGACY_HORIZON = math.pi / 2 - 0.001
# Hosek-Wilkie's XYZ is in the model's physical units (W m^-2 sr^-1 per channel, Y times
# 683 lm/W a luminance); Cycles scales it by 2 pi / 683 into its scene linear units.
HOSEK_SCALE = 2.0 * math.pi / 683.0


def _perez(coefficients, theta, gamma):
    """Perez et al.'s all-weather sky luminance distribution, the five coefficients A..E."""
    a, b, c, d, e = coefficients
    return (1.0 + a * np.exp(b / np.cos(theta))) * (1.0 + c * np.exp(d * gamma) + e * np.cos(gamma) ** 2)


def _preetham(turbidity: float, sun_theta: float):
    """Preetham, Shirley and Smits' (1999) fit for turbidity T: the Perez coefficients of Y, x
    and y, and the zenith's Y (in their kcd/m^2, times 0.06 as Cycles scales it), x and y,
    each divided by its Perez function at the zenith so that the function times it is the sky."""
    t, s = float(turbidity), float(sun_theta)
    perez = (((0.1787, -1.4630), (-0.3554, 0.4275), (-0.0227, 5.3251), (0.1206, -2.5771), (-0.0670, 0.3703)),
             ((-0.0193, -0.2592), (-0.0665, 0.0008), (-0.0004, 0.2125), (-0.0641, -0.8989), (-0.0033, 0.0452)),
             ((-0.0167, -0.2608), (-0.0950, 0.0092), (-0.0079, 0.2102), (-0.0441, -1.6537), (-0.0109, 0.0529)))
    coefficients = [tuple(k * t + c for k, c in row) for row in perez]
    chi = (4.0 / 9.0 - t / 120.0) * (math.pi - 2.0 * s)
    zenith_luminance = ((4.0453 * t - 4.9710) * math.tan(chi) - 0.2155 * t + 2.4192) * 0.06
    # The zenith's chromaticity: cubics in the sun's zenith angle, quadratic in T.
    s3 = np.array([s ** 3, s ** 2, s, 1.0])
    tt = np.array([t * t, t, 1.0])
    zx = tt @ np.array([[0.00166, -0.00375, 0.00209, 0.0], [-0.02903, 0.06377, -0.03202, 0.00394],
                        [0.11693, -0.21196, 0.06052, 0.25886]]) @ s3
    zy = tt @ np.array([[0.00275, -0.00610, 0.00317, 0.0], [-0.04214, 0.08970, -0.04153, 0.00516],
                        [0.15346, -0.26756, 0.06670, 0.26688]]) @ s3
    zenith = [z / _perez(c, 0.0, s) for z, c in zip((zenith_luminance, zx, zy), coefficients)]
    return coefficients, zenith


def _hosek_wilkie(turbidity: float, albedo: float, elevation: float):
    """Hosek and Wilkie's (2012) model for a turbidity in [1, 10], a ground albedo in [0, 1] and
    a sun elevation in [0, pi/2]: per XYZ channel, the nine coefficients of their extended Perez
    function and the channel's radiance scale, each a quintic Bezier over the cube root of the
    elevation's fraction of 90 degrees, interpolated linearly between the fitted integer
    turbidities and the two albedos (as the authors' implementation cooks them)."""
    from .hosek_wilkie_data import CONFIGS, RADIANCES

    t = min(max(float(turbidity), 1.0), 10.0)
    a = min(max(float(albedo), 0.0), 1.0)
    x = (min(max(float(elevation), 0.0), math.pi / 2) / (math.pi / 2)) ** (1.0 / 3.0)
    bezier = np.array([(1 - x) ** 5, 5 * (1 - x) ** 4 * x, 10 * (1 - x) ** 3 * x ** 2, 10 * (1 - x) ** 2 * x ** 3,
                       5 * (1 - x) * x ** 4, x ** 5])
    low = int(t)
    rest = t - low
    weights = {}  # (albedo index, turbidity index): weight
    for turb, wt in ((low, 1.0 - rest), (low + 1, rest)):
        if wt > 0.0 and turb <= 10:
            weights[0, turb - 1] = (1.0 - a) * wt
            weights[1, turb - 1] = a * wt
    configs = np.array(CONFIGS).reshape(3, 2, 10, 6, 9)
    radiances = np.array(RADIANCES).reshape(3, 2, 10, 6)
    config = sum(w * np.einsum("k,ckj->cj", bezier, configs[:, i, j]) for (i, j), w in weights.items())
    radiance = sum(w * radiances[:, i, j] @ bezier for (i, j), w in weights.items())
    return config, radiance


class LegacySky:
    """The Sky Texture's Preetham or Hosek-Wilkie model, as Cycles evaluates it: a function of
    the direction alone (no table, no sun disc), for a Sun Direction (Blender's world frame),
    a Turbidity and (Hosek-Wilkie) a Ground Albedo."""

    sun_disc, size = False, 0.0  # what the world bake asks of a sky with a disc

    def __init__(self, kind: str, sun_direction=(0.0, 0.0, 1.0), turbidity: float = 2.2, ground_albedo: float = 0.3):
        if kind not in ("PREETHAM", "HOSEK_WILKIE"):
            raise ValueError(f"not a legacy sky model: {kind!r}")
        sun = np.asarray(sun_direction, np.float64)
        length = float(np.linalg.norm(sun))
        self.sun_direction = sun / length if length > 0 else np.array([0.0, 0.0, 1.0])
        self.kind = kind
        theta = math.acos(min(max(self.sun_direction[2], -1.0), 1.0))
        if kind == "PREETHAM":
            self._coefficients, self._zenith = _preetham(turbidity, theta)
        else:
            # The sun below the horizon is the model's sun at the horizon (the fit's range).
            theta = min(theta, math.pi / 2)
            self._config, self._radiance = _hosek_wilkie(turbidity, ground_albedo, math.pi / 2 - theta)
        self.sun_theta = theta

    def sky(self, directions: np.ndarray) -> np.ndarray:
        """The sky (N, 3 scene linear) along unit `directions`."""
        d = np.asarray(directions, np.float64)
        cos_theta = np.clip(d[:, 2], -1.0, 1.0)
        # The angle to the sun from the directions' own (unclamped) zenith angle.
        gamma = np.arccos(np.clip(d @ self._sun_for_gamma(), -1.0, 1.0))
        theta = np.minimum(np.arccos(cos_theta), LEGACY_HORIZON)
        if self.kind == "PREETHAM":
            luminance, x, y = (z * _perez(c, theta, gamma) for z, c in zip(self._zenith, self._coefficients))
            with np.errstate(divide="ignore", invalid="ignore"):
                xyz = np.stack([np.where(y != 0, x / y * luminance, 0.0), luminance,
                                np.where((y != 0) & (luminance != 0), (1.0 - x - y) / y * luminance, 0.0)], -1)
            return xyz_to_rgb(xyz)
        c = self._config
        cos_t, cos_g = np.cos(theta)[:, None], np.cos(gamma)[:, None]
        g = gamma[:, None]
        mie = (1.0 + cos_g ** 2) / (1.0 + c[:, 8] ** 2 - 2.0 * c[:, 8] * cos_g) ** 1.5
        xyz = ((1.0 + c[:, 0] * np.exp(c[:, 1] / (cos_t + 0.01)))
               * (c[:, 2] + c[:, 3] * np.exp(c[:, 4] * g) + c[:, 5] * cos_g ** 2 + c[:, 6] * mie
                  + c[:, 7] * np.sqrt(cos_t))) * self._radiance
        return xyz_to_rgb(xyz) * HOSEK_SCALE

    def _sun_for_gamma(self) -> np.ndarray:
        """The sun the angle gamma is measured from: its direction at the zenith angle the
        model was set up with (Hosek-Wilkie's clamped at the horizon)."""
        s = self.sun_direction
        horizontal = math.hypot(s[0], s[1])
        if horizontal == 0.0:
            return np.array([0.0, 0.0, math.cos(self.sun_theta)])
        k = math.sin(self.sun_theta) / horizontal
        return np.array([s[0] * k, s[1] * k, math.cos(self.sun_theta)])


# ------------------------------------------------------------------------------------------
# A Sky Texture inside a material (a backdrop card, a sky seen in a mirror ball): baked once
# into an equirectangular image, looked up at the node's vector as an Environment Texture is.

# 1024 x 512 (~0.35 degree a pixel), as a world's bake: looked up with Linear interpolation,
# the sky within 0.3 % of the model's own value everywhere above the horizon's band
# (tests/render/test_sky_texture_node.py measures it).
MATERIAL_SKY_WIDTH = 1024


def equirectangular_directions(width: int, height: int) -> np.ndarray:
    """(height, width, 3) unit directions of an equirectangular image's pixel centres, row 0
    at the nadir, u = 0.5 along +X and increasing towards -Y: Cycles' layout of a world (and
    of an Environment Texture's Equirectangular lookup)."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    phi = (0.5 - u)[None, :] * 2.0 * np.pi
    elevation = (v - 0.5)[:, None] * np.pi
    c = np.cos(elevation)
    return np.stack(np.broadcast_arrays(c * np.cos(phi), c * np.sin(phi), np.sin(elevation) + 0 * phi), axis=-1)


def sky_image(model, width: int = MATERIAL_SKY_WIDTH) -> np.ndarray:
    """(width / 2, width, 4) float32 RGBA, bottom row first: `model` (Sky or LegacySky) at
    the pixels' directions without a sun disc, alpha 1."""
    height = width // 2
    d = equirectangular_directions(width, height).reshape(-1, 3)
    out = np.ones((height * width, 4), np.float32)
    rgb = np.concatenate([model.sky(d[i:i + 65536]) for i in range(0, len(d), 65536)])
    out[:, :3] = rgb
    return out.reshape(height, width, 4)
