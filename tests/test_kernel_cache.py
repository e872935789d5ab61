"""model.kernel_cache drops numba's cache files when any source under the package changed (numba
alone misses a change in a file a kernel calls into), and only then."""

from pathlib import Path

from model.kernel_cache import ROOT, STAMP, drop_stale_kernels, sources_digest


def _tree(root: Path) -> dict[str, Path]:
    files = {"source": root / "formulas.py", "other": root / "sub" / "walk.py",
             "index": root / "__pycache__" / "walk.step-10.py311.nbi",
             "kernel": root / "sub" / "__pycache__" / "walk.step-10.py311.1.nbc",
             "bytecode": root / "__pycache__" / "formulas.cpython-311.pyc"}
    for name, path in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(f"{name} = 1\n")
    return files


def test_caches_go_when_a_source_changes_and_stay_otherwise(tmp_path):
    files = _tree(tmp_path)
    assert drop_stale_kernels(tmp_path)  # no digest kept yet: whatever is cached is unknown
    assert not files["index"].exists() and not files["kernel"].exists()
    assert files["bytecode"].exists() and files["source"].exists()
    assert (tmp_path / STAMP).read_text() == sources_digest(tmp_path)

    files["index"].write_text("compiled from these sources")
    assert not drop_stale_kernels(tmp_path)
    assert files["index"].exists()

    files["source"].write_text("source = 2\n")  # e.g. a pull that edits primitives.py alone
    assert drop_stale_kernels(tmp_path)
    assert not files["index"].exists()
    assert not drop_stale_kernels(tmp_path)


def test_importing_sim_keeps_the_digest_of_its_sources():
    assert (ROOT / STAMP).read_text() == sources_digest(ROOT)
