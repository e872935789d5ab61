"""Mitsuba 3 BSDF plugins of gonio's exports: `gonio_multiscatter`, a nested single-scattering
BSDF plus the energy that scattering more than once adds, as cosine lobes whose albedo follows a
table; and `gonio_coated`, the `lambert+microfacet` family (model.bsdf.families.coated).

The table gives, at incidence angles `theta_deg` from the normal of the side the light arrives
on, the reflectance and transmittance that the nested BSDF lacks, from outside (+z) and from
inside; values between the angles are interpolated linearly. The lobes take their albedo at the
light's direction (si.wi in importance mode, wo in radiance mode, as Mitsuba's own BSDFs swap the
two), so the directional albedo of light arriving from any direction is the nested BSDF's plus
the table's. Imports only mitsuba and drjit: gonio's Mitsuba export writes this file beside
the XML, and a script that renders the XML calls register() first (a scene file cannot load a
Python plugin). Non-polarized variants only.

`gonio_coated` is gonio's CoatedDiffuse: a nested coat (Mitsuba's `roughplastic` with a black
base, whose value is gonio's coat lobe) plus rho/pi (1 - a(i)) (1 - a(o)) / (1 - a_mean), a(mu)
the coat's directional albedo as gonio tabulates it (`albedo_mu`, `albedo`: linear in mu, held
below the first cosine) and a_mean its cosine-weighted mean (`albedo_mean`); sampled as gonio
samples it (the coat with probability a(i) / (a(i) + rho (1 - a(i))), else the cosine lobe).
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

PLUGIN_NAME = "gonio_multiscatter"
COATED_NAME = "gonio_coated"
#: Table properties: reflectance and transmittance of light arriving from outside and inside.
TABLES = ("reflectance_outside", "transmittance_outside", "reflectance_inside",
          "transmittance_inside")
#: Bounds of the probability of sampling the added lobes (they stay reachable either way).
LOBE_CHOICE_BOUNDS = (0.05, 0.95)


def _numbers(props, name: str) -> list[float]:
    """A comma-separated list of numbers property."""
    return [float(x) for x in str(props[name]).split(",")]


def _interpolated(x, nodes: list[float], values: list[float]):
    """values at x, linear between nodes, held at the end values beyond them."""
    out = x * 0.0 + values[0]
    for k in range(len(nodes) - 1):
        share = dr.clip((x - nodes[k]) / (nodes[k + 1] - nodes[k]), 0.0, 1.0)
        out = dr.select(x > nodes[k], values[k] + share * (values[k + 1] - values[k]), out)
    return out


def _nested(props, plugin: str):
    """The one nested BSDF of the plugin's properties."""
    nested = [props[k] for k in props.keys() if isinstance(props[k], mi.BSDF)]
    if len(nested) != 1:
        raise RuntimeError(f"{plugin}: needs exactly one nested bsdf, got {len(nested)}")
    return nested[0]


def _refuse_polarized(plugin: str) -> None:
    """A RuntimeError in a polarized variant, which the plugins do not support."""
    if mi.is_polarized:
        raise RuntimeError(f"{plugin}: polarized variants are not supported")


class MultipleScatteringMethods:
    """The nested BSDF plus the tabulated cosine lobes (see the module docstring): the methods
    register() gives a mitsuba.BSDF subclass of the variant in use (nanobind takes one base)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        _refuse_polarized(PLUGIN_NAME)
        self.single = _nested(props, PLUGIN_NAME)
        self.eta = float(props["ior"])
        self.theta = _numbers(props, "theta_deg")
        self.tables = {name: _numbers(props, name) for name in TABLES}
        if any(len(t) != len(self.theta) for t in self.tables.values()):
            raise RuntimeError(f"{PLUGIN_NAME}: every table needs one value per theta_deg")
        reflection = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
        transmission = (mi.BSDFFlags.GlossyTransmission | mi.BSDFFlags.FrontSide
                        | mi.BSDFFlags.BackSide | mi.BSDFFlags.NonSymmetric)
        self.m_components = [reflection, transmission]
        self.m_flags = reflection | transmission

    def _table(self, name: str, theta_deg):
        """The table `name` at theta_deg, linear between its angles, constant beyond them."""
        return _interpolated(theta_deg, self.theta, self.tables[name])

    def _albedos(self, light):
        """(reflectance, transmittance) the lobes add for light arriving along `light`."""
        outside = mi.Frame3f.cos_theta(light) > 0
        theta = dr.acos(dr.clip(dr.abs(mi.Frame3f.cos_theta(light)), 0.0, 1.0)) * (180 / math.pi)
        r = dr.select(outside, self._table("reflectance_outside", theta),
                      self._table("reflectance_inside", theta))
        t = dr.select(outside, self._table("transmittance_outside", theta),
                      self._table("transmittance_inside", theta))
        return r, t

    def _lobes(self, ctx, si, wo):
        """(f |cos wo| of the lobes at wo, their density of wo, the probability of sampling
        them): the albedos at the light's direction give the value, those at si.wi the
        sampling (a choice sample() can make before it knows wo)."""
        light = si.wi if ctx.mode == mi.TransportMode.Importance else wo
        r, t = self._albedos(si.wi)
        r_light, t_light = self._albedos(light)
        same = mi.Frame3f.cos_theta(si.wi) * mi.Frame3f.cos_theta(wo) > 0
        cos_o = dr.abs(mi.Frame3f.cos_theta(wo))
        value = dr.select(same, r_light, t_light) * cos_o / math.pi
        share_r = self._reflect_share(r, t)
        pdf = dr.select(same, share_r, 1.0 - share_r) * cos_o / math.pi
        return value, pdf, self._choice(r, t)

    @staticmethod
    def _reflect_share(r, t):
        """Probability of sampling the added reflection rather than the added transmission."""
        total = r + t
        return dr.select(total > 0, r / dr.select(total > 0, total, 1.0), 0.5)

    @staticmethod
    def _choice(r, t):
        """Probability of sampling the added lobes rather than the nested BSDF."""
        return dr.clip(r + t, *LOBE_CHOICE_BOUNDS)

    def eval(self, ctx, si, wo, active=True):
        """f |cos wo|: the nested BSDF's plus the lobes'."""
        return self.single.eval(ctx, si, wo, active) + mi.Spectrum(self._lobes(ctx, si, wo)[0])

    def pdf(self, ctx, si, wo, active=True):
        """Density of sample()'s wo: the mixture of the nested BSDF's and the lobes'."""
        _, lobe_pdf, choice = self._lobes(ctx, si, wo)
        return (1.0 - choice) * self.single.pdf(ctx, si, wo, active) + choice * lobe_pdf

    def eval_pdf(self, ctx, si, wo, active=True):
        """eval() and pdf() together."""
        value, pdf = self.single.eval_pdf(ctx, si, wo, active)
        lobe_value, lobe_pdf, choice = self._lobes(ctx, si, wo)
        return value + mi.Spectrum(lobe_value), (1.0 - choice) * pdf + choice * lobe_pdf

    def sample(self, ctx, si, sample1, sample2, active=True):
        """The nested BSDF's sample or a cosine-lobe direction (reflected or transmitted), with
        the weight of the mixture (f |cos wo| / its pdf)."""
        r, t = self._albedos(si.wi)
        choice = self._choice(r, t)
        use_lobe = sample1 < choice
        rescaled = dr.select(use_lobe, sample1 / choice, (sample1 - choice) / (1.0 - choice))
        share_r = self._reflect_share(r, t)
        reflect = rescaled < share_r
        local = mi.warp.square_to_cosine_hemisphere(sample2)
        up = mi.Frame3f.cos_theta(si.wi) > 0
        flip = up != reflect
        lobe_wo = mi.Vector3f(local.x, local.y, dr.select(flip, -local.z, local.z))
        bs, single_weight = self.single.sample(ctx, si, rescaled, sample2, active)
        # a sample the nested BSDF fails (weight 0, though its pdf may be positive) stays
        # failed: counting it at eval() / pdf() would add energy its sampler never reaches
        single_ok = (bs.pdf > 0) & dr.any(single_weight != 0)
        wo = dr.select(use_lobe, lobe_wo, bs.wo)
        value, pdf = self.eval_pdf(ctx, si, wo, active)
        transmitted = mi.Frame3f.cos_theta(si.wi) * mi.Frame3f.cos_theta(wo) < 0
        bs.wo = wo
        bs.pdf = pdf
        bs.eta = dr.select(transmitted, dr.select(up, self.eta, 1.0 / self.eta), 1.0)
        bs.sampled_type = dr.select(
            transmitted, mi.UInt32(+mi.BSDFFlags.GlossyTransmission),
            mi.UInt32(+mi.BSDFFlags.GlossyReflection))
        bs.sampled_component = dr.select(transmitted, mi.UInt32(1), mi.UInt32(0))
        ok = active & (pdf > 0) & (use_lobe | single_ok)
        return bs, dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)

    def to_string(self):
        """The plugin and its nested BSDF."""
        return f"{PLUGIN_NAME}[single = {self.single}, theta_deg = {self.theta}]"


class CoatedDiffuseMethods:
    """The coat plus the coupled Lambertian base (the module docstring): the methods register()
    gives a mitsuba.BSDF subclass of the variant in use."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        _refuse_polarized(COATED_NAME)
        self.coat = _nested(props, COATED_NAME)
        self.rho = float(props["rho"])
        self.mu, self.albedo = _numbers(props, "albedo_mu"), _numbers(props, "albedo")
        self.mean = float(props["albedo_mean"])
        if len(self.mu) != len(self.albedo) or len(self.mu) < 2:
            raise RuntimeError(f"{COATED_NAME}: albedo_mu and albedo need the same length (>= 2)")
        glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        diffuse = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        self.m_components = [glossy, diffuse]
        self.m_flags = glossy | diffuse

    def _base(self, si, wo):
        """(the base's f cos wo at wo, its density of wo), 0 unless both are above."""
        cos_i, cos_o = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
        up = (cos_i > 0) & (cos_o > 0)
        a_i = _interpolated(cos_i, self.mu, self.albedo)
        a_o = _interpolated(cos_o, self.mu, self.albedo)
        value = self.rho / math.pi * (1.0 - a_i) * (1.0 - a_o) / (1.0 - self.mean) * cos_o
        return dr.select(up, value, 0.0), dr.select(up, cos_o / math.pi, 0.0)

    def _coat_probability(self, si):
        """Probability of sampling the coat at si.wi: its share of the reflected energy."""
        a = _interpolated(mi.Frame3f.cos_theta(si.wi), self.mu, self.albedo)
        total = a + self.rho * (1.0 - a)
        return dr.select(total > 0, a / dr.select(total > 0, total, 1.0), 1.0)

    def eval(self, ctx, si, wo, active=True):
        """f cos wo: the coat's plus the base's."""
        return self.coat.eval(ctx, si, wo, active) + mi.Spectrum(self._base(si, wo)[0])

    def pdf(self, ctx, si, wo, active=True):
        """Density of sample()'s wo: the mixture of the coat's and the cosine lobe's."""
        p = self._coat_probability(si)
        return p * self.coat.pdf(ctx, si, wo, active) + (1.0 - p) * self._base(si, wo)[1]

    def eval_pdf(self, ctx, si, wo, active=True):
        """eval() and pdf() together."""
        value, pdf = self.coat.eval_pdf(ctx, si, wo, active)
        base, base_pdf = self._base(si, wo)
        p = self._coat_probability(si)
        return value + mi.Spectrum(base), p * pdf + (1.0 - p) * base_pdf

    def sample(self, ctx, si, sample1, sample2, active=True):
        """The coat's sample or a cosine-lobe direction, with the mixture's weight."""
        p = self._coat_probability(si)
        use_base = sample1 >= p
        rescaled = dr.select(use_base, (sample1 - p) / (1.0 - p), sample1 / p)
        bs, coat_weight = self.coat.sample(ctx, si, rescaled, sample2, active)
        # a sample the coat fails stays failed (as gonio_multiscatter's nested one)
        coat_ok = (bs.pdf > 0) & dr.any(coat_weight != 0)
        wo = dr.select(use_base, mi.warp.square_to_cosine_hemisphere(sample2), bs.wo)
        value, pdf = self.eval_pdf(ctx, si, wo, active)
        bs.wo, bs.pdf, bs.eta = wo, pdf, 1.0
        bs.sampled_type = dr.select(use_base, mi.UInt32(+mi.BSDFFlags.DiffuseReflection),
                                    mi.UInt32(+mi.BSDFFlags.GlossyReflection))
        bs.sampled_component = dr.select(use_base, mi.UInt32(1), mi.UInt32(0))
        ok = (active & (pdf > 0) & (use_base | coat_ok)
              & (mi.Frame3f.cos_theta(si.wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0))
        return bs, dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)

    def to_string(self):
        """The plugin, its coat and base albedo."""
        return f"{COATED_NAME}[coat = {self.coat}, rho = {self.rho}]"


def register() -> None:
    """Make `gonio_multiscatter` and `gonio_coated` known to Mitsuba's loader in the variant in
    use (call it after mitsuba.set_variant, once per variant)."""
    for name, methods_class, class_name in (
            (PLUGIN_NAME, MultipleScatteringMethods, "MultipleScatteringBSDF"),
            (COATED_NAME, CoatedDiffuseMethods, "CoatedDiffuseBSDF")):
        methods = {key: value for key, value in vars(methods_class).items()
                   if key == "__init__" or not key.startswith("__")}
        bsdf = type(class_name, (mi.BSDF,), methods)
        mi.register_bsdf(name, lambda props, bsdf=bsdf: bsdf(props))
