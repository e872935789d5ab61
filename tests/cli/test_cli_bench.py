"""`gonio bench`: README sections are rewritten between their markers and nowhere else."""

import pytest

from gonio.errors import GonioError
from gonio_cli.commands.bench import update_readme


def test_update_readme_replaces_only_the_marked_block(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text(
        "intro\n<!-- bench:x:begin -->\nold\n<!-- bench:x:end -->\n"
        "<!-- bench:y:begin -->\nkeep\n<!-- bench:y:end -->\n"
    )
    update_readme(readme, "x", "new figure 3.5\n")
    text = readme.read_text()
    assert "new figure 3.5" in text and "old" not in text
    assert "keep" in text and text.startswith("intro\n")


def test_update_readme_without_markers_names_the_script(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("no markers here\n")
    with pytest.raises(GonioError, match="bench script z"):
        update_readme(readme, "z", "x")
