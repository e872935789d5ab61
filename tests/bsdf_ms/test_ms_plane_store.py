"""HigherOrderLobe's planes on disk (plane_store): read back bit for bit by a later lobe, named
by everything the walk depends on, walked again (one warning) where a file does not match its
digest (altered, torn, another shape), and a disk that refuses the file (a real file-size
limit) or a cache folder another user could write into leaves the build whole in memory."""

import json
import os
import resource
import stat
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from model.bsdf import RoughDielectric
from model.bsdf.multiple_scattering import HigherOrderLobe, plane_store
from model.bsdf.multiple_scattering.plane_store import PlaneStore, cache_root, code_digest
from sim.bench.sample import higher_order_lobe

GLASS = RoughDielectric("ggx", 0.5, 1.51, masking="correlated")
PARENT = {"distribution": "ggx", "alpha": 0.5, "eta": 1.51, "masking": "correlated"}
WI = np.array([np.sin(np.radians(30.0)), 0.0, np.cos(np.radians(30.0))])
WO = np.array([[0.5, 0.0, -0.866], [-0.3, 0.0, -0.954], [0.2, 0.0, 0.98]])


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """GONIO_CACHE_DIR pointed at an empty directory; its planes' folder."""
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path))
    return tmp_path / "ms-planes"


def lobe(cached: bool = True, **kwargs):
    return HigherOrderLobe(GLASS, **{"walks": 512, "seed": 4, **kwargs},
                           cache_as=PARENT if cached else None)


def address_of(path: Path) -> tuple[int, ...]:
    """A plane file's address, from its name (KEY-side-node-plane-hemisphere.npz)."""
    return tuple(int(part) for part in path.stem.split("-")[1:])


def stored(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(plane, digest) as a plane file holds them."""
    with np.load(path) as archive:
        return archive["plane"], archive["digest"]


def cache_warnings(action) -> tuple[object, list[str]]:
    """What action() returns and the cache's warnings it gave, each one counted."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = action()
    return result, [str(w.message) for w in caught if "cache" in str(w.message)]


def test_a_later_lobe_reads_the_planes_back(cache):
    first = lobe().estimate(WI, WO)
    files = sorted(cache.glob("*.npz"))
    assert len(files) == 2 and not list(cache.glob("*.partial"))  # both hemispheres
    np.testing.assert_array_equal(lobe(cached=False).estimate(WI, WO), first)  # as walked
    np.testing.assert_array_equal(lobe().estimate(WI, WO), first)
    # it is the file that is read: a changed file (with its digest) changes what a lobe gives
    plane, _ = stored(files[0])
    assert lobe().store.save(address_of(files[0]), 2.0 * plane)
    assert not np.array_equal(lobe().estimate(WI, WO)[0], first[0])


def test_everything_the_values_depend_on_names_the_files(cache):
    """The lobe's walks, seed, grid and order-2 switch and every parent parameter (and the
    code, through code_digest) give the files' key: a lobe never reads another's tables."""
    keys = {lobe(**kwargs).store.key for kwargs in (
        {}, {"walks": 1024}, {"seed": 5}, {"theta_step_deg": 5.0}, {"phi_step_deg": 30.0},
        {"exact_second": False})}
    for name, value in (("alpha", 0.5001), ("eta", 1.5), ("distribution", "beckmann"),
                        ("masking", "separable")):
        keys.add(HigherOrderLobe(GLASS, walks=512, seed=4,
                                 cache_as={**PARENT, name: value}).store.key)
    assert len(keys) == 10
    assert PlaneStore({"a": 1}, cache).key == PlaneStore({"a": 1}, cache).key


def test_other_code_names_other_files(cache, monkeypatch):
    """code_digest: model.bsdf's sources and numpy's, scipy's and numba's versions; a change of
    any gives other files."""
    assert code_digest().count("-") == 3 and np.__version__ in code_digest()
    before = PlaneStore(PARENT, cache).key
    monkeypatch.setattr(plane_store, "code_digest", lambda: "edited-sources")
    assert PlaneStore(PARENT, cache).key != before


@pytest.mark.parametrize("damage", ["truncated", "other shape", "not finite", "not numpy",
                                    "no digest", "a bare array"])
def test_a_damaged_file_is_walked_again_and_replaced(cache, damage):
    expected = lobe().estimate(WI, WO)
    path = sorted(cache.glob("*.npz"))[0]
    good = path.read_bytes()
    plane, digest = stored(path)
    if damage == "truncated":
        path.write_bytes(good[: len(good) // 2])
    elif damage == "other shape":  # a file whose digest matches its plane, of another shape
        lobe().store.save(address_of(path), np.zeros((5, 3)))
    elif damage == "not finite":
        with path.open("wb") as handle:
            np.savez(handle, plane=np.full(plane.shape, np.nan), digest=digest)
    elif damage == "not numpy":
        path.write_text("not a plane")
    elif damage == "no digest":
        with path.open("wb") as handle:
            np.savez(handle, plane=plane)
    else:
        with path.open("wb") as handle:
            np.save(handle, plane)
    values, said = cache_warnings(lambda: lobe().estimate(WI, WO))
    np.testing.assert_array_equal(values, expected)
    assert path.read_bytes() == good
    assert len(said) == 1 and "does not match its digest" in said[0]


def test_tables_multiplied_by_100_on_disk_are_walked_again_with_one_warning(cache):
    """The attack: every plane file's values times 100, its digest kept. A later lobe gives
    the clean cache's values, says so once, and the files hold the clean planes again."""
    clean = lobe().estimate(WI, WO)
    files = sorted(cache.glob("*.npz"))
    good = [path.read_bytes() for path in files]
    for path in files:
        plane, digest = stored(path)
        with path.open("wb") as handle:
            np.savez(handle, plane=100.0 * plane, digest=digest)
    values, said = cache_warnings(lambda: lobe().estimate(WI, WO))
    np.testing.assert_array_equal(values, clean)
    assert len(said) == 1 and str(cache) in said[0], said
    assert [path.read_bytes() for path in files] == good


def test_a_plane_copied_from_another_address_is_walked_again(cache):
    """A file's digest covers what it was built from: another plane's whole file, put in
    this one's place, does not pass."""
    clean = lobe().estimate(WI, WO)
    first, second = sorted(cache.glob("*.npz"))
    good = second.read_bytes()
    second.write_bytes(first.read_bytes())
    values, said = cache_warnings(lambda: lobe().estimate(WI, WO))
    np.testing.assert_array_equal(values, clean)
    assert len(said) == 1 and second.read_bytes() == good


def test_a_world_writable_cache_directory_is_not_used(tmp_path, monkeypatch):
    """A cache directory of mode 0777: one warning naming it, the lobe's values those of a
    lobe without a store, and nothing written there; a planted file is not read."""
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o777)
    monkeypatch.setenv("GONIO_CACHE_DIR", str(shared))
    values, said = cache_warnings(lambda: [lobe().estimate(WI, WO) for _ in range(2)])
    np.testing.assert_array_equal(values[0], lobe(cached=False).estimate(WI, WO))
    assert len(said) == 1 and f"{shared} is not used: world-writable (mode 0777)" in said[0]
    assert list(shared.iterdir()) == []


def test_a_group_writable_planes_folder_is_not_used(cache):
    """The rule covers the folders gonio makes under the cache directory too."""
    lobe().estimate(WI, WO)
    cache.chmod(0o770)
    files = {path: path.read_bytes() for path in cache.iterdir()}
    for path in files:
        plane, digest = stored(path)
        with path.open("wb") as handle:
            np.savez(handle, plane=100.0 * plane, digest=digest)
    values, said = cache_warnings(lambda: lobe().estimate(WI, WO))
    np.testing.assert_array_equal(values, lobe(cached=False).estimate(WI, WO))
    assert len(said) == 1 and "group-writable (mode 0770)" in said[0]


@pytest.mark.skipif(os.geteuid() != 0, reason="giving a folder to another user takes root")
def test_a_cache_directory_owned_by_another_user_is_not_used(tmp_path, monkeypatch):
    """The attack: a cache directory owned by `nobody` (uid 65534), mode 0755 so nobody
    else may write there, is still nobody's to fill: not read, not written."""
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    os.chown(theirs, 65534, 65534)
    monkeypatch.setenv("GONIO_CACHE_DIR", str(theirs))
    values, said = cache_warnings(lambda: lobe().estimate(WI, WO))
    np.testing.assert_array_equal(values, lobe(cached=False).estimate(WI, WO))
    assert len(said) == 1 and f"owned by uid 65534, not {os.geteuid()}" in said[0]
    assert list(theirs.iterdir()) == []


def planted(cache, path: Path) -> Path:
    """The attack's file: `path`'s plane times 100 with a digest made for it (the digest
    is no secret), written as another user could while the folder was 0777, which the user
    then made 0700 again."""
    plane, _ = stored(path)
    store = lobe().store
    with open(path, "wb") as handle:
        np.savez(handle, plane=100.0 * plane,
                 digest=np.array(store.digest(address_of(path), 100.0 * plane)))
    path.chmod(0o666)
    cache.chmod(0o700)
    return path


@pytest.mark.skipif(os.geteuid() != 0, reason="giving a file to another user takes root")
def test_a_plane_file_another_user_planted_is_walked_again(cache):
    """A plane file owned by `nobody`, mode 0666, values x100 and a digest that matches
    them, in a folder that passes the rule now: walked again and replaced, one warning."""
    clean = lobe().estimate(WI, WO)
    path = planted(cache, sorted(cache.glob("*.npz"))[0])
    os.chown(path, 65534, 65534)
    values, said = cache_warnings(lambda: lobe().estimate(WI, WO))
    np.testing.assert_array_equal(values, clean)
    assert len(said) == 1 and f"not this user's alone (owned by uid 65534, not " \
        f"{os.geteuid()})" in said[0], said
    assert path.stat().st_uid == os.geteuid() and path.stat().st_mode & 0o077 == 0


def test_a_plane_file_writable_by_others_or_a_symlink_is_walked_again(cache, tmp_path):
    """The same planted plane, this user's but world-writable; then a symbolic link to it
    in a plane's place (never followed): each walked again and replaced, one warning."""
    clean = lobe().estimate(WI, WO)
    first, second = sorted(cache.glob("*.npz"))
    planted(cache, first)
    values, said = cache_warnings(lambda: lobe().estimate(WI, WO))
    np.testing.assert_array_equal(values, clean)
    assert len(said) == 1 and "not this user's alone (world-writable (mode 0666))" in said[0]
    elsewhere = planted(cache, second).rename(tmp_path / "elsewhere.npz")
    elsewhere.chmod(0o600)
    second.symlink_to(elsewhere)
    values, said = cache_warnings(lambda: lobe().estimate(WI, WO))
    np.testing.assert_array_equal(values, clean)
    assert len(said) == 1 and "not this user's alone (a symbolic link)" in said[0]
    assert not second.is_symlink()


def test_a_cache_under_a_sticky_world_writable_folder_is_used(tmp_path, monkeypatch):
    """Only the cache directory and the folders gonio makes are checked, not their parents:
    a cache under a /tmp-like folder (mode 1777) is made 0700 and read back."""
    sticky = tmp_path / "tmp"
    sticky.mkdir()
    sticky.chmod(0o1777)
    monkeypatch.setenv("GONIO_CACHE_DIR", str(sticky / "gonio-cache"))
    first, said = cache_warnings(lambda: lobe().estimate(WI, WO))
    planes = sticky / "gonio-cache" / "ms-planes"
    assert said == [] and len(list(planes.glob("*.npz"))) == 2
    for folder in (sticky / "gonio-cache", planes):
        assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    np.testing.assert_array_equal(lobe().estimate(WI, WO), first)


SCRIPT = """
import json, sys
import numpy as np
from pathlib import Path
from model.bsdf import RoughDielectric
from model.bsdf.multiple_scattering import HigherOrderLobe
from model.bsdf.multiple_scattering.plane_store import PlaneStore
glass = RoughDielectric("ggx", 0.5, 1.51, masking="correlated")
wi, wo = np.array(json.loads(sys.argv[2])), np.array(json.loads(sys.argv[3]))
values = HigherOrderLobe(glass, 512, 4, cache_as=json.loads(sys.argv[1])).estimate(wi, wo)
print(json.dumps([v.tolist() for v in values]))
"""


def test_a_disk_that_refuses_the_file_leaves_the_build_in_memory(tmp_path):
    """Every file the process writes is limited to 100 bytes (RLIMIT_FSIZE: the kernel refuses
    the write with EFBIG): the lobe's values are those of a lobe without a store, and no file,
    whole or partial, is left."""
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (100, 100))

    done = subprocess.run([sys.executable, "-c", SCRIPT, json.dumps(PARENT),
                           json.dumps(WI.tolist()), json.dumps(WO.tolist())],
                          capture_output=True, text=True, timeout=300, preexec_fn=limit,
                          env={**os.environ, "GONIO_CACHE_DIR": str(tmp_path)})
    assert done.returncode == 0, done.stderr
    np.testing.assert_array_equal(np.array(json.loads(done.stdout)),
                                  np.array(lobe(cached=False).estimate(WI, WO)))
    assert [p.name for p in tmp_path.rglob("*") if p.is_file()] == []


def test_the_cache_directory_follows_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path / "here"))
    assert cache_root() == tmp_path / "here"
    monkeypatch.setenv("GONIO_CACHE_DIR", "off")
    assert cache_root() is None and lobe().store is None
    monkeypatch.delenv("GONIO_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_root() == tmp_path / "xdg" / "gonio"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/dir")  # ignored, as the XDG spec says
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_root() == tmp_path / "home" / ".cache" / "gonio"


def test_no_home_directory_means_no_cache(monkeypatch):
    """A process with no HOME and no passwd entry (a container's unknown user): Path.home()
    raises, and the lobe keeps its tables in memory."""
    def no_home() -> Path:
        raise RuntimeError("Could not determine home directory.")

    monkeypatch.delenv("GONIO_CACHE_DIR", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setattr(Path, "home", staticmethod(no_home))
    assert cache_root() is None and lobe().store is None


def test_the_bench_keeps_its_tables_in_the_cache_directory(tmp_path, monkeypatch):
    monkeypatch.setenv("GONIO_CACHE_DIR", str(tmp_path))
    higher_order_lobe.cache_clear()
    try:
        bench_lobe = higher_order_lobe("hemisphere", "ggx", 0.5, 1.51, 0.0, 512, 4)
        values = bench_lobe.estimate(WI, WO)
    finally:
        higher_order_lobe.cache_clear()
    assert len(list((tmp_path / "ms-planes").glob("*.npz"))) == 2
    np.testing.assert_array_equal(values, lobe(cached=False).estimate(WI, WO))
