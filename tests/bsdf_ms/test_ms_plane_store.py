"""HigherOrderLobe's planes on disk (plane_store): read back bit for bit by a later lobe, named
by everything the walk depends on, walked again where a file is torn or of another shape, and
a disk that refuses the file (a real file-size limit) leaves the build whole in memory."""

import json
import resource
import subprocess
import sys

import numpy as np
import pytest

from sim.bench.sample import higher_order_lobe
from sim.bsdf import RoughDielectric
from sim.bsdf.multiple_scattering import HigherOrderLobe
from sim.bsdf.multiple_scattering.plane_store import PlaneStore, cache_root, plane_store

GLASS = RoughDielectric("ggx", 0.5, 1.51, masking="correlated")
DESCRIPTION = {"distribution": "ggx", "alpha": 0.5, "eta": 1.51, "walks": 512, "seed": 4}
WI = np.array([np.sin(np.radians(30.0)), 0.0, np.cos(np.radians(30.0))])
WO = np.array([[0.5, 0.0, -0.866], [-0.3, 0.0, -0.954], [0.2, 0.0, 0.98]])


def lobe(store):
    return HigherOrderLobe(GLASS, walks=512, seed=4, store=store)


def test_a_later_lobe_reads_the_planes_back(tmp_path):
    store = PlaneStore(DESCRIPTION, tmp_path)
    first = lobe(store).estimate(WI, WO)
    files = sorted(store.folder.glob("*.npy"))
    assert len(files) == 2 and not list(store.folder.glob("*.partial"))  # both hemispheres
    np.testing.assert_array_equal(lobe(None).estimate(WI, WO), first)  # as walked in memory
    np.testing.assert_array_equal(lobe(PlaneStore(DESCRIPTION, tmp_path)).estimate(WI, WO),
                                  first)
    # it is the file that is read: a changed file changes what a new lobe gives
    plane = np.load(files[0])
    np.save(files[0], 2.0 * plane)
    assert not np.array_equal(lobe(PlaneStore(DESCRIPTION, tmp_path)).estimate(WI, WO)[0],
                              first[0])


def test_every_parameter_and_the_code_name_the_file(tmp_path):
    keys = {PlaneStore({**DESCRIPTION, name: value}, tmp_path).key
            for name, value in [("walks", 512), ("walks", 1024), ("seed", 5), ("alpha", 0.5001),
                                ("eta", 1.5)]}
    assert len(keys) == 5


@pytest.mark.parametrize("damage", ["truncated", "other shape", "not finite", "not numpy"])
def test_a_damaged_file_is_walked_again_and_replaced(tmp_path, damage):
    store = PlaneStore(DESCRIPTION, tmp_path)
    expected = lobe(store).estimate(WI, WO)
    path = sorted(store.folder.glob("*.npy"))[0]
    good = path.read_bytes()
    if damage == "truncated":
        path.write_bytes(good[: len(good) // 2])
    elif damage == "other shape":
        np.save(path, np.zeros((5, 3)))
    elif damage == "not finite":
        np.save(path, np.full(np.load(path).shape, np.nan))
    else:
        path.write_text("not a plane")
    np.testing.assert_array_equal(lobe(PlaneStore(DESCRIPTION, tmp_path)).estimate(WI, WO),
                                  expected)
    assert path.read_bytes() == good


SCRIPT = """
import json, sys
import numpy as np
from pathlib import Path
from sim.bsdf import RoughDielectric
from sim.bsdf.multiple_scattering import HigherOrderLobe
from sim.bsdf.multiple_scattering.plane_store import PlaneStore
glass = RoughDielectric("ggx", 0.5, 1.51, masking="correlated")
store = PlaneStore(json.loads(sys.argv[1]), Path(sys.argv[2]))
wi, wo = np.array(json.loads(sys.argv[3])), np.array(json.loads(sys.argv[4]))
values = HigherOrderLobe(glass, 512, 4, store=store).estimate(wi, wo)
print(json.dumps([v.tolist() for v in values]))
"""


def test_a_disk_that_refuses_the_file_leaves_the_build_in_memory(tmp_path):
    """Every file the process writes is limited to 100 bytes (RLIMIT_FSIZE: the kernel refuses
    the write with EFBIG): the lobe's values are those of a lobe without a store, and no file,
    whole or partial, is left."""
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (100, 100))

    done = subprocess.run([sys.executable, "-c", SCRIPT, json.dumps(DESCRIPTION), str(tmp_path),
                           json.dumps(WI.tolist()), json.dumps(WO.tolist())],
                          capture_output=True, text=True, timeout=300, preexec_fn=limit)
    assert done.returncode == 0, done.stderr
    np.testing.assert_array_equal(np.array(json.loads(done.stdout)),
                                  np.array(lobe(None).estimate(WI, WO)))
    assert [p.name for p in tmp_path.rglob("*") if p.is_file()] == []


def test_the_cache_directory_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "here"))
    assert cache_root() == tmp_path / "here"
    monkeypatch.setenv("GONIO_CACHE_DIR", "off")
    assert cache_root() is None and plane_store(DESCRIPTION) is None
    monkeypatch.delenv("GONIO_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_root() == tmp_path / "xdg" / "gonio"


def test_the_bench_keeps_its_tables_in_the_cache_directory(tmp_path, monkeypatch):
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path))
    higher_order_lobe.cache_clear()
    try:
        bench_lobe = higher_order_lobe("hemisphere", "ggx", 0.5, 1.51, 0.0, 512, 4)
        values = bench_lobe.estimate(WI, WO)
    finally:
        higher_order_lobe.cache_clear()
    assert len(list((tmp_path / "ms-planes").glob("*.npy"))) == 2
    np.testing.assert_array_equal(values, lobe(None).estimate(WI, WO))
