"""Mitsuba 3 BSDF plugin `gonio_multiscatter`: a nested single-scattering BSDF plus the energy
that scattering more than once adds, as cosine lobes whose albedo follows a table.

The table gives, at incidence angles `theta_deg` from the normal of the side the light arrives
on, the reflectance and transmittance that the nested BSDF lacks, from outside (+z) and from
inside; values between the angles are interpolated linearly. The lobes take their albedo at the
light's direction (si.wi in importance mode, wo in radiance mode, as Mitsuba's own BSDFs swap the
two), so the directional albedo of light arriving from any direction is the nested BSDF's plus
the table's. Imports only mitsuba and drjit: gonio's Mitsuba export writes this file beside
the XML, and a script that renders the XML calls register() first (a scene file cannot load a
Python plugin). Non-polarized variants only.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

PLUGIN_NAME = "gonio_multiscatter"
#: Table properties: reflectance and transmittance of light arriving from outside and inside.
TABLES = ("reflectance_outside", "transmittance_outside", "reflectance_inside",
          "transmittance_inside")
#: Bounds of the probability of sampling the added lobes (they stay reachable either way).
LOBE_CHOICE_BOUNDS = (0.05, 0.95)


def _numbers(props, name: str) -> list[float]:
    """A comma-separated list of numbers property."""
    return [float(x) for x in str(props[name]).split(",")]


class MultipleScatteringMethods:
    """The nested BSDF plus the tabulated cosine lobes (see the module docstring): the methods
    register() gives a mitsuba.BSDF subclass of the variant in use (nanobind takes one base)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        if mi.is_polarized:
            raise RuntimeError(f"{PLUGIN_NAME}: polarized variants are not supported")
        nested = [props[k] for k in props.keys() if isinstance(props[k], mi.BSDF)]
        if len(nested) != 1:
            raise RuntimeError(f"{PLUGIN_NAME}: needs exactly one nested bsdf, got {len(nested)}")
        self.single = nested[0]
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
        values, nodes = self.tables[name], self.theta
        out = theta_deg * 0.0 + values[0]
        for k in range(len(nodes) - 1):
            share = dr.clip((theta_deg - nodes[k]) / (nodes[k + 1] - nodes[k]), 0.0, 1.0)
            out = dr.select(theta_deg > nodes[k], values[k] + share * (values[k + 1] - values[k]),
                            out)
        return out

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


def register() -> None:
    """Make `gonio_multiscatter` known to Mitsuba's loader in the variant in use (call it after
    mitsuba.set_variant, once per variant)."""
    methods = {name: value for name, value in vars(MultipleScatteringMethods).items()
               if name == "__init__" or not name.startswith("__")}
    bsdf = type("MultipleScatteringBSDF", (mi.BSDF,), methods)
    mi.register_bsdf(PLUGIN_NAME, lambda props: bsdf(props))
