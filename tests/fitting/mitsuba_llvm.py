"""The llvm_mitsuba fixture: Mitsuba 3 with its LLVM variant (mitsuba_albedo.VARIANT) running
here, for the tests that sample or render with it; else a skip, or a failure where the
conformance suite is required (required_tools)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from mitsuba_albedo import VARIANT
from required_tools import tool_missing

#: Dr.Jit's LLVM backend aborts the process with too old an LLVM (docs/performance.md): tried
#: in a child process first.
LLVM_PROBE = ("import mitsuba as mi; mi.set_variant('llvm_ad_rgb'); "
              "b = mi.load_dict({'type': 'roughdielectric'}); "
              "si = mi.SurfaceInteraction3f(); si.wi = mi.Vector3f(0, 0, 1); "
              "print(b.sample(mi.BSDFContext(), si, mi.Float(0.5), mi.Point2f(0.5, 0.5))[1])")


@pytest.fixture(scope="module")
def llvm_mitsuba():
    """Mitsuba 3 (the `mitsuba` extra, in `test`) with its LLVM variant running here
    (libllvm19 or newer); else a skip or, where the conformance suite is required, a
    failure (required_tools)."""
    probe = subprocess.run([sys.executable, "-c", LLVM_PROBE], capture_output=True, text=True)
    if probe.returncode != 0:
        tool_missing(f"Mitsuba's {VARIANT} does not start (install mitsuba and libllvm19): "
                     f"{probe.stderr.strip()[-200:]}")
