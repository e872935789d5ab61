"""`gonio bench`: lists the scripts, runs one or all, and rewrites a doc between markers only."""

import pytest

from gonio.errors import GonioError
from gonio_cli.commands import bench
from gonio_cli.commands.bench import update_doc
from gonio_cli.main import main


def test_update_doc_replaces_only_the_marked_block(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(
        "intro\n<!-- bench:x:begin -->\nold\n<!-- bench:x:end -->\n"
        "<!-- bench:y:begin -->\nkeep\n<!-- bench:y:end -->\n"
    )
    update_doc(readme, "x", "new figure 3.5\n")
    text = readme.read_text()
    assert "new figure 3.5" in text and "old" not in text
    assert "keep" in text and text.startswith("intro\n")


def test_update_doc_without_markers_names_the_script(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("no markers here\n")
    with pytest.raises(GonioError, match="bench script z"):
        update_doc(readme, "z", "x")


@pytest.fixture
def scripts(tmp_path, monkeypatch):
    """A bench/ folder of two quick scripts; each leaves a file behind when it runs."""
    folder = tmp_path / "bench"
    folder.mkdir()
    for name, figure in (("alpha", "1.5"), ("beta", "2.5")):
        (folder / f"{name}.py").write_text(
            f'"""Measures {name} in one line.\n\nMore detail.\n"""\n'
            f"from pathlib import Path\nPath(__file__).with_suffix('.ran').touch()\n"
            f"print('{name} figure {figure}')\n")
    monkeypatch.setattr(bench, "BENCH_DIR", folder)
    return folder


def test_no_name_lists_every_script_with_its_one_line_summary(scripts, capsys):
    assert main(["bench"]) == 0
    assert capsys.readouterr().out.splitlines() == ["alpha  Measures alpha in one line.",
                                                    "beta   Measures beta in one line."]
    assert not list(scripts.glob("*.ran"))


def test_all_runs_every_script_and_doc_rewrites_their_blocks(scripts, tmp_path, capsys):
    doc = tmp_path / "performance.md"
    doc.write_text("".join(f"## {n}\n<!-- bench:{n}:begin -->\nold\n<!-- bench:{n}:end -->\n"
                           for n in ("alpha", "beta")))
    assert main(["bench", "all", "--doc", str(doc)]) == 0
    assert capsys.readouterr().out == "== alpha\nalpha figure 1.5\n== beta\nbeta figure 2.5\n"
    text = doc.read_text()
    assert "alpha figure 1.5" in text and "beta figure 2.5" in text and "old" not in text


def test_missing_markers_fail_before_any_script_runs(scripts, tmp_path, capsys):
    doc = tmp_path / "performance.md"
    doc.write_text("<!-- bench:alpha:begin -->\n<!-- bench:alpha:end -->\n")
    assert main(["bench", "all", "--doc", str(doc)]) == 2
    assert "markers for bench script beta" in capsys.readouterr().err
    assert not list(scripts.glob("*.ran"))


def test_a_bare_doc_before_the_names_is_explained(scripts, capsys):
    assert main(["bench", "--doc", "all"]) == 2
    assert "`gonio bench all --doc` writes into performance.md" in capsys.readouterr().err


def test_every_bench_script_has_a_summary_and_a_block_in_docs_performance():
    scripts = bench.available()
    bench.check_markers(bench.DEFAULT_DOC, list(scripts))
    assert all(bench.summary(path) != "(no description)" for path in scripts.values())
