"""Tests of regrasp_cli.store: hashes, atomic writes, HDF5 artefacts and their refusals."""

from __future__ import annotations

import dataclasses
from datetime import datetime
from pathlib import Path

import h5py
import numpy as np
import pytest

from regrasp_cli import __version__
from regrasp_cli.errors import CorruptArtefactError, InputError, StaleArtefactError
from regrasp_cli.store import (
    Provenance,
    atomic_write,
    atomic_write_bytes,
    atomic_write_text,
    content_digest,
    file_label,
    is_fresh,
    read_artefact,
    read_provenance,
    robot_identity,
    sha256_bytes,
    sha256_file,
    sha256_params,
    why_not_fresh,
    write_artefact,
)

H = {name: sha256_bytes(name.encode()) for name in ("urdf", "robot_yaml", "mesh", "params")}
PROV = Provenance("regrasp.grasps", 2, H)


def _datasets() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    return {
        "grasps/hand_in_object": rng.normal(size=(5, 4, 4)),
        "grasps/ids": np.arange(5, dtype=np.int32),
        "grasps/valid": np.array([True, False, True, True, False]),
        "scores": rng.random(5).astype(np.float32),
    }


def _groups() -> dict[str, dict[str, np.ndarray]]:
    return {"roadmap/level1": {"edges": np.array([[0, 1], [1, 2]], dtype=np.int64), "names": np.array(["a", "bé"])}}


@pytest.fixture
def artefact(tmp_path: Path) -> Path:
    path = tmp_path / "cache" / "grasps.h5"
    write_artefact(path, PROV, _datasets(), attrs={"hand": "left", "n": 5, "eps": 0.5}, groups=_groups())
    return path


# ------------------------------------------------------------------------ hashes


def test_sha256_bytes_and_file(tmp_path: Path) -> None:
    assert sha256_bytes(b"abc") == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    f = tmp_path / "x.bin"
    f.write_bytes(b"abc" * 1_000_000)
    assert sha256_file(f) == sha256_bytes(b"abc" * 1_000_000)


def test_sha256_params_canonical_and_order_independent() -> None:
    assert sha256_params({"a": 0.1, "b": [1, None, True]}) == sha256_bytes(b'{"a":0.1,"b":[1,null,true]}')
    assert sha256_params({"x": 1, "y": {"p": 2, "q": 3}}) == sha256_params({"y": {"q": 3, "p": 2}, "x": 1})
    assert sha256_params({"x": 1}) != sha256_params({"x": 2})


def test_sha256_params_int_and_float_are_distinct() -> None:
    assert sha256_params(1) != sha256_params(1.0)
    assert sha256_params(0.0) != sha256_params(-0.0)


def test_sha256_params_numpy_tuples_dataclasses() -> None:
    assert sha256_params((1, 2)) == sha256_params([1, 2])
    assert sha256_params(np.float64(0.25)) == sha256_params(0.25)
    assert sha256_params(np.int32(3)) == sha256_params(3)
    assert sha256_params(np.bool_(True)) == sha256_params(True)
    assert sha256_params(np.eye(2)) == sha256_params([[1.0, 0.0], [0.0, 1.0]])

    @dataclasses.dataclass(frozen=True)
    class P:
        step: float
        n: int

    assert sha256_params(P(0.5, 3)) == sha256_params({"n": 3, "step": 0.5})


@pytest.mark.parametrize("bad", [{1: "a"}, {"s": {1, 2}}, Path("x"), object()])
def test_sha256_params_rejects_non_canonical(bad: object) -> None:
    with pytest.raises(TypeError):
        sha256_params(bad)


# ----------------------------------------------------------------- atomic writes


def test_atomic_write_creates_parent_and_leaves_no_temp(tmp_path: Path) -> None:
    target = tmp_path / "a" / "b" / "out.txt"
    atomic_write_text(target, "hello")
    assert target.read_text() == "hello"
    atomic_write_bytes(target, b"bye")
    assert target.read_bytes() == b"bye"
    assert sorted(p.name for p in target.parent.iterdir()) == ["out.txt"]


def test_atomic_write_failure_keeps_old_file(tmp_path: Path) -> None:
    target = tmp_path / "out.txt"
    target.write_text("old")
    seen: list[Path] = []

    def writer(tmp: Path) -> None:
        seen.append(tmp)
        tmp.write_text("half-writ")
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        atomic_write(target, writer)
    assert target.read_text() == "old"
    assert seen[0].parent == tmp_path and seen[0].name.startswith(".out.txt.") and seen[0].name.endswith(".tmp")
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_write_artefact_failure_keeps_old_artefact(artefact: Path) -> None:
    before = artefact.read_bytes()
    with pytest.raises(TypeError):
        write_artefact(artefact, PROV, {"ok": np.zeros(3), "bad": np.array([object()])})
    assert artefact.read_bytes() == before
    # no temp file left (the artefact's lock file stays, as filelock leaves it)
    assert sorted(p.name for p in artefact.parent.iterdir()) == ["grasps.h5", "grasps.h5.lock"]


# --------------------------------------------------------------------- round trip


def test_round_trip(artefact: Path) -> None:
    art = read_artefact(artefact, PROV)
    expected = _datasets() | {"roadmap/level1/" + k: v for k, v in _groups()["roadmap/level1"].items()}
    assert set(art.data) == set(expected)
    for name, arr in expected.items():
        assert art[name].dtype == arr.dtype, name
        assert art[name].shape == arr.shape, name
        np.testing.assert_array_equal(art[name], arr)
    assert art.attrs == {"hand": "left", "n": 5, "eps": 0.5}
    assert type(art.attrs["n"]) is int and type(art.attrs["eps"]) is float
    p = art.provenance
    assert (p.format, p.format_version, dict(p.inputs)) == ("regrasp.grasps", 2, H)
    assert p.software_version == __version__
    assert p.created.endswith("Z") and datetime.fromisoformat(p.created.replace("Z", "+00:00"))
    assert read_provenance(artefact) == p


def test_layout_on_disk(artefact: Path) -> None:
    with h5py.File(artefact, "r") as f:
        assert f.attrs["format"] == "regrasp.grasps"
        assert f.attrs["input_sha256.mesh"] == H["mesh"]
        assert isinstance(f["grasps"], h5py.Group)
        assert f["roadmap/level1/edges"].shape == (2, 2)


def test_write_is_deterministic(tmp_path: Path) -> None:
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    write_artefact(a, PROV, _datasets(), groups=_groups())
    write_artefact(b, PROV, _datasets(), groups=_groups())
    da, db = read_artefact(a, PROV).data, read_artefact(b, PROV).data
    assert {k: sha256_bytes(v.tobytes()) for k, v in da.items()} == {k: sha256_bytes(v.tobytes()) for k, v in db.items()}


def test_missing_dataset_names_it(artefact: Path) -> None:
    with pytest.raises(InputError) as e:
        read_artefact(artefact, PROV)["nope"]
    assert e.value.field == "nope"


@pytest.mark.parametrize("attrs", [{"format": "x"}, {"input_sha256.urdf": "x"}, {"flag": True}])
def test_write_rejects_reserved_or_bad_attrs(tmp_path: Path, attrs: dict) -> None:
    with pytest.raises((ValueError, TypeError)):
        write_artefact(tmp_path / "x.h5", PROV, {}, attrs=attrs)
    assert not (tmp_path / "x.h5").exists()


# ---------------------------------------------------------------------- refusals


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such artefact") as e:
        read_artefact(tmp_path / "none.h5", PROV)
    assert e.value.field is None and not isinstance(e.value, StaleArtefactError)
    assert "regrasp grasps build" in e.value.message


@pytest.mark.parametrize("content, what", [(b"", "the file is empty"),
                                           (b"garbage, not an HDF5 file\n" * 50, "not a readable HDF5 file")])
def test_garbage_file_is_damaged(tmp_path: Path, content: bytes, what: str) -> None:
    path = tmp_path / "bad.h5"
    path.write_bytes(content)
    with pytest.raises(CorruptArtefactError, match=what) as e:
        read_artefact(path, PROV)
    assert e.value.message.startswith("damaged artefact") and e.value.message.endswith("`regrasp grasps build`")
    with pytest.raises(CorruptArtefactError, match=what):
        read_provenance(path)


def test_truncated_file_is_damaged(artefact: Path) -> None:
    data = artefact.read_bytes()
    artefact.write_bytes(data[: len(data) // 2])
    with pytest.raises(CorruptArtefactError, match="truncated"):
        read_artefact(artefact, PROV)
    assert not is_fresh(artefact, PROV)


def _flip_middle(path: Path, n: int = 64) -> None:
    """XOR ``n`` bytes in the middle of the file (where the datasets are)."""
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid:mid + n] = bytes(b ^ 0xFF for b in data[mid:mid + n])
    path.write_bytes(bytes(data))


def test_flipped_bytes_that_hdf5_reads_are_caught_by_the_checksum(tmp_path: Path) -> None:
    path = tmp_path / "big.h5"
    write_artefact(path, PROV, {"nodes": np.random.default_rng(1).normal(size=(2000, 43))})
    _flip_middle(path)
    with h5py.File(path, "r") as f:  # HDF5 itself sees nothing wrong
        assert f["nodes"].shape == (2000, 43)
    with pytest.raises(CorruptArtefactError, match="do not match the checksum") as e:
        read_artefact(path, PROV)
    assert isinstance(e.value, StaleArtefactError)  # rebuilt like a stale one
    assert not is_fresh(path, PROV)
    assert "do not match the checksum" in why_not_fresh(path, PROV)


def test_a_changed_attribute_is_caught_by_the_checksum(artefact: Path) -> None:
    with h5py.File(artefact, "r+") as f:
        f.attrs["n"] = 6
    with pytest.raises(CorruptArtefactError):
        read_artefact(artefact, PROV)


def test_an_artefact_without_checksum_is_stale(artefact: Path) -> None:
    with h5py.File(artefact, "r+") as f:
        del f.attrs["content_sha256"]
    with pytest.raises(StaleArtefactError) as e:
        read_artefact(artefact, PROV)
    assert e.value.field == "content_sha256" and not isinstance(e.value, CorruptArtefactError)


def test_content_digest_is_the_same_before_writing_and_after_reading(artefact: Path) -> None:
    art = read_artefact(artefact, PROV)
    written = _datasets() | {"roadmap/level1/" + k: v for k, v in _groups()["roadmap/level1"].items()}
    assert content_digest(art.attrs, art.data) == content_digest({"hand": "left", "n": 5, "eps": 0.5}, written)
    other = dict(written, scores=written["scores"] + 1)
    assert content_digest(art.attrs, other) != content_digest(art.attrs, written)


def test_foreign_hdf5_file(tmp_path: Path) -> None:
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as f:
        f["x"] = np.zeros(3)
    with pytest.raises(InputError, match="not a regrasp artefact") as e:
        read_artefact(path, PROV)
    assert e.value.field == "format"


def test_wrong_format(artefact: Path) -> None:
    with pytest.raises(InputError) as e:
        read_artefact(artefact, Provenance("regrasp.roadmap", 2, H))
    assert e.value.field == "format" and not isinstance(e.value, StaleArtefactError)
    assert e.value.message == "expected 'regrasp.roadmap', found 'regrasp.grasps'"


def test_older_format_version_is_stale(artefact: Path) -> None:
    with pytest.raises(StaleArtefactError) as e:
        read_artefact(artefact, Provenance("regrasp.grasps", 3, H))
    assert e.value.field == "format_version" and "found 2" in e.value.message


def test_newer_format_version_is_refused(artefact: Path) -> None:
    with pytest.raises(InputError) as e:
        read_artefact(artefact, Provenance("regrasp.grasps", 1, H))
    assert e.value.field == "format_version" and not isinstance(e.value, StaleArtefactError)
    assert "newer regrasp" in e.value.message


def test_stale_single_input(artefact: Path) -> None:
    current = H | {"mesh": sha256_bytes(b"other mesh")}
    with pytest.raises(StaleArtefactError) as e:
        read_artefact(artefact, Provenance("regrasp.grasps", 2, current))
    assert e.value.field == "input_sha256.mesh"
    msg = e.value.message
    assert "was built for a different mesh" in msg
    assert f"stored {H['mesh'][:12]}…" in msg and f"current {current['mesh'][:12]}…" in msg
    assert msg.endswith("rebuild it with `regrasp grasps build`")
    assert "urdf" not in msg and str(artefact) in str(e.value)


def test_stale_names_every_input(artefact: Path) -> None:
    current = {k: v for k, v in H.items() if k != "params"} | {
        "urdf": sha256_bytes(b"u2"),
        "robot_yaml": sha256_bytes(b"r2"),
        "extra": sha256_bytes(b"e"),
    }
    with pytest.raises(StaleArtefactError) as e:
        read_artefact(artefact, Provenance("regrasp.grasps", 2, current), rebuild="regrasp grasps build --robot r.yaml")
    msg = e.value.message
    for name in ("urdf", "robot_yaml", "params", "extra"):
        assert name in msg, name
    assert "mesh" not in msg
    assert msg.endswith("`regrasp grasps build --robot r.yaml`")


def test_is_fresh(artefact: Path, tmp_path: Path) -> None:
    assert is_fresh(artefact, PROV)
    assert not is_fresh(tmp_path / "none.h5", PROV)
    assert not is_fresh(artefact, Provenance("regrasp.grasps", 2, H | {"urdf": sha256_bytes(b"x")}))
    assert not is_fresh(artefact, Provenance("regrasp.grasps", 3, H))
    with pytest.raises(InputError):
        is_fresh(artefact, Provenance("regrasp.roadmap", 2, H))
    garbage = tmp_path / "garbage.h5"
    garbage.write_bytes(b"junk")
    assert not is_fresh(garbage, PROV)  # damaged: rebuilt
    assert why_not_fresh(tmp_path / "none.h5", PROV) == "missing" and why_not_fresh(artefact, PROV) is None


# --------------------------------------------------------------------------- robot identity


@dataclasses.dataclass(frozen=True)
class _Hand:
    grasp_frame: str
    fingers: tuple[str, ...]


def _robot(file: str, urdf: str = "u", hands: dict | None = None):
    """What robot_identity reads of a Robot: spec.file, spec.hands, urdf_sha256."""
    from types import SimpleNamespace

    hands = {"right": _Hand("r_palm", ("a", "b")), "left": _Hand("l_palm", ("a", "b"))} if hands is None else hands
    return SimpleNamespace(spec=SimpleNamespace(file=Path(file), hands=hands), urdf_sha256=sha256_bytes(urdf.encode()))


def test_robot_identity_is_the_folder_or_stem_and_a_hash_of_urdf_and_hands() -> None:
    ident = robot_identity(_robot("/x/robots/baxter/robot.yaml"))
    name, digest = ident.rsplit("-", 1)
    assert name == "baxter" and len(digest) == 8 and int(digest, 16) >= 0
    assert robot_identity(_robot("/y/other/place/baxter/robot.yaml")) == ident  # only the folder's name counts
    assert robot_identity(_robot("/x/my bot.yaml")).startswith("my_bot-")  # the stem, made safe
    assert robot_identity(_robot("/x/robots/baxter/robot.yaml", urdf="v")) != ident
    other_hands = {"right": _Hand("r_palm", ("a",)), "left": _Hand("l_palm", ("a", "b"))}
    assert robot_identity(_robot("/x/robots/baxter/robot.yaml", hands=other_hands)) != ident
    swapped = {"left": _Hand("l_palm", ("a", "b")), "right": _Hand("r_palm", ("a", "b"))}
    assert robot_identity(_robot("/x/robots/baxter/robot.yaml", hands=swapped)) == ident  # order of hands


def test_file_label() -> None:
    assert file_label("builtin_block") == "builtin_block"
    assert file_label("a b/c:d") == "a_b_c_d" and file_label("") == "_"
