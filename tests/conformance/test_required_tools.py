"""The conformance suite's missing tools (tests/required_tools.py): a skip naming the tool, a
failure where GONIO_REQUIRE_CONFORMANCE=1; libbsdf's build tells a missing tool (which CI
installs) from a missing snapshot (which it cannot), and only the first fails in CI."""

from __future__ import annotations

import pytest
from libbsdf_reader import ReaderUnavailable, ToolMissing, build_probe
from required_tools import REQUIRE, require_module, tool_missing


def test_a_missing_tool_skips_unless_the_conformance_suite_is_required(monkeypatch):
    monkeypatch.delenv(REQUIRE, raising=False)
    with pytest.raises(pytest.skip.Exception, match="cmake not found"):
        tool_missing("cmake not found")
    monkeypatch.setenv(REQUIRE, "1")
    with pytest.raises(pytest.fail.Exception, match=r"cmake not found \(GONIO_REQUIRE_"):
        tool_missing("cmake not found")
    with pytest.raises(pytest.fail.Exception, match="a reader: No module named 'no_such_mod"):
        require_module("no_such_module_here", "a reader")


def test_libbsdf_tells_a_missing_compiler_from_a_missing_snapshot(monkeypatch, tmp_path):
    snapshot = tmp_path / "third_party" / "libbsdf"
    snapshot.mkdir(parents=True)
    monkeypatch.setenv("GONIO_THIRD_PARTY", str(tmp_path / "third_party"))
    with pytest.raises(ReaderUnavailable, match="no libbsdf snapshot") as caught:
        build_probe()
    assert not isinstance(caught.value, ToolMissing)
    (snapshot / "CMakeLists.txt").write_text("project(libbsdf)\n")
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    with pytest.raises(ToolMissing, match="cmake not found"):
        build_probe()
