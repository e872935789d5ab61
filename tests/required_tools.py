"""The tools the conformance suite's readers need (a C++ compiler, CMake, Eigen, a Python
reader, Mitsuba's LLVM variant): a test that lacks one skips with the reason, or fails where
GONIO_REQUIRE_CONFORMANCE=1 (.ci/run's conformance step, which installs them), so that CI
cannot pass by skipping. A missing ../shared/third_party snapshot, which CI cannot install,
is not a tool: its tests skip either way."""

from __future__ import annotations

import importlib
import os
from types import ModuleType
from typing import NoReturn

import pytest

REQUIRE = "GONIO_REQUIRE_CONFORMANCE"


def tool_missing(reason: str) -> NoReturn:
    """Skip the test (or module) for a missing tool, naming it; fail instead where REQUIRE=1."""
    if os.environ.get(REQUIRE) == "1":
        pytest.fail(f"{reason} ({REQUIRE}=1: the conformance step needs it)", pytrace=False)
    pytest.skip(reason, allow_module_level=True)


def require_module(name: str, reason: str) -> ModuleType:
    """The module `name`, imported; tool_missing(reason) where it is not installed."""
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        tool_missing(f"{reason}: {exc}")
