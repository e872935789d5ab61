"""model.kernel_cache drops numba's cache files when any source under the package changed (numba
alone misses a change in a file a kernel calls into), and only then; a cache file the disk
refuses leaves the compiled kernel working in memory, as does a cache folder another user could
write into."""

import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

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


KERNEL = """
from model.kernel_cache import compiled


@compiled(error_model="numpy")
def twice(x):
    return 2.0 * x
"""


def run_kernel(tmp_path: Path, cache: Path, preexec=None) -> subprocess.CompletedProcess:
    """Compile and call a kernel of model.kernel_cache.compiled in a new process whose numba
    cache directory is `cache`."""
    (tmp_path / "kernel.py").write_text(KERNEL)
    path = os.pathsep.join([str(tmp_path), str(ROOT.parent), os.environ.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, "-c", "import kernel; print(kernel.twice(21.0))"],
                          capture_output=True, text=True, timeout=300, preexec_fn=preexec,
                          env={**os.environ, "NUMBA_CACHE_DIR": str(cache),
                               "PYTHONPATH": path, "PYTHONDONTWRITEBYTECODE": "1"})


@pytest.mark.parametrize("limit_bytes", [100, None])
def test_a_kernel_whose_cache_file_the_disk_refuses_still_runs(tmp_path, limit_bytes):
    """Every file the process writes limited to 100 bytes (RLIMIT_FSIZE: EFBIG, as under `ulimit
    -f`): the kernel compiles and runs, one warning names the cache folder, no file is left;
    without the limit numba caches it as usual."""
    pytest.importorskip("numba")
    cache = tmp_path / "numba"

    def limit() -> None:
        if limit_bytes is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    done = run_kernel(tmp_path, cache, limit)
    assert (done.returncode, done.stdout) == (0, "42.0\n"), done.stderr
    written = sorted(p.suffix for p in cache.rglob("*") if p.is_file())
    if limit_bytes is None:
        assert written == [".nbc", ".nbi"] and "refused" not in done.stderr
    else:
        assert written == [] and done.stderr.count("refused a write (File too large)") == 1


def test_a_world_writable_kernel_cache_is_neither_read_nor_written(tmp_path):
    """NUMBA_CACHE_DIR of mode 0777 (numba's index files are pickles another user could plant
    there): the kernel compiles and runs, one warning names the folder, no file is written;
    a kernel cached in it while it was private is not read once it is not."""
    pytest.importorskip("numba")
    cache = tmp_path / "numba"
    cache.mkdir(mode=0o700)
    assert run_kernel(tmp_path, cache).returncode == 0
    files = [p for p in cache.rglob("*") if p.is_file()]
    assert sorted(p.suffix for p in files) == [".nbc", ".nbi"]
    for index in (p for p in files if p.suffix == ".nbi"):
        index.write_bytes(b"planted")  # what another user's pickle would be; read, it fails
    cached = {p: p.stat().st_mtime_ns for p in files}
    cache.chmod(0o777)
    done = run_kernel(tmp_path, cache)
    assert (done.returncode, done.stdout) == (0, "42.0\n"), done.stderr
    assert done.stderr.count(f"{cache} is not used: world-writable (mode 0777)") == 1
    assert {p: p.stat().st_mtime_ns for p in cache.rglob("*") if p.is_file()} == cached
