"""Content hashes, atomic writes and provenance-stamped HDF5 artefacts.

Offline artefacts (grasp lists, roadmaps, ...) are cached in HDF5 files that record
which inputs they were built from, so a stale cache is refused instead of silently
used.  Every file is written atomically (temp file in the same directory, fsync,
``os.replace``): a crash or an exception never leaves a half-written artefact.

On-disk layout of an artefact (one HDF5 file)::

    /                                   root group
      @format            str            kind of artefact, e.g. "regrasp.grasps"
      @format_version    int            layout version of that kind
      @software_version  str            regrasp_cli.__version__ of the writer
      @created           str            ISO-8601 UTC, e.g. "2024-05-01T12:00:00Z"
      @input_sha256.<name>  str         sha256 hex of each input ("urdf", "mesh", ...)
      @content_sha256    str            sha256 hex of the datasets and caller attributes
      @<attr>            str|int|float  caller attributes (any other name)
      <dataset>                         datasets, nested paths like "grasps/hand_in_object"
      <group>/<dataset>                 datasets of the ``groups`` argument

Provenance lives in prefixed *root* attributes (not a subgroup), so the attribute
name ``input_sha256.<name>`` is also the field named in a :class:`StaleArtefactError`.
Datasets are written in sorted order without timestamps: the same inputs give the
same datasets; only ``@created`` differs between two builds.

Freshness rules of :func:`read_artefact`: a missing file or a different ``format`` is an
:class:`InputError`; an *older* ``format_version`` or any input-hash difference is a
:class:`StaleArtefactError`, and a file that cannot be read (truncated, empty, damaged)
or whose contents do not match ``content_sha256`` a :class:`CorruptArtefactError` (for
both, rebuilding fixes it and :func:`is_fresh` answers ``False``); a *newer*
``format_version`` is an :class:`InputError` (the file comes from a newer regrasp).

``content_sha256`` (:func:`content_digest`) covers every dataset (name, dtype, shape,
bytes) and the caller attributes, so flipped bytes in the middle of a file, which HDF5
itself reads without complaint, are caught when the artefact is loaded.

:func:`sha256_params` hashes canonical JSON (sorted keys, no spaces, floats via
``repr``).  ``int`` and ``float`` are distinct (``1`` and ``1.0`` hash differently);
tuples hash like lists; numpy scalars/arrays hash like the Python values of
``.item()``/``.tolist()``; dataclasses hash like ``dataclasses.asdict``.
"""

from __future__ import annotations

import dataclasses
import glob
import hashlib
import json
import os
import re
import socket
import tempfile
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Protocol

import h5py
import numpy as np
from filelock import FileLock

from regrasp_cli import __version__
from regrasp_cli.errors import CorruptArtefactError, InputError, StaleArtefactError

__all__ = [
    "Artefact",
    "ExpectedProvenance",
    "Provenance",
    "artefact_lock",
    "atomic_write",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_writable",
    "canonical_json",
    "content_digest",
    "file_label",
    "is_fresh",
    "why_not_fresh",
    "read_artefact",
    "read_provenance",
    "robot_identity",
    "sha256_bytes",
    "sha256_file",
    "sha256_params",
    "write_artefact",
]

INPUT_PREFIX = "input_sha256."
CHECKSUM_ATTR = "content_sha256"
_PROVENANCE_ATTRS = ("format", "format_version", "software_version", "created", CHECKSUM_ATTR)
_CHUNK = 1 << 20

AttrValue = str | int | float


# --------------------------------------------------------------------------- hashes


def sha256_bytes(b: bytes) -> str:
    """Hex sha256 of ``b``."""
    return hashlib.sha256(b).hexdigest()


def sha256_file(path: str | Path) -> str:
    """Hex sha256 of a file's content (streamed; ``OSError`` if unreadable)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def _canonical(obj: Any) -> Any:
    """``obj`` as JSON-native values; ``TypeError`` for anything without a canonical form."""
    if isinstance(obj, np.ndarray):
        obj = obj.tolist()
    elif isinstance(obj, np.generic):
        obj = obj.item()
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        obj = dataclasses.asdict(obj)
    if obj is None or isinstance(obj, (str, bool, int, float)):
        return obj
    if isinstance(obj, Mapping):
        out: dict[str, Any] = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise TypeError(f"sha256_params: dict key {k!r} is not a str")
            out[k] = _canonical(v)
        return out
    if isinstance(obj, (list, tuple)):
        return [_canonical(v) for v in obj]
    raise TypeError(f"sha256_params: cannot hash a {type(obj).__name__}")


def canonical_json(obj: Any) -> str:
    """The canonical JSON text hashed by :func:`sha256_params`."""
    return json.dumps(_canonical(obj), sort_keys=True, separators=(",", ":"), ensure_ascii=False)


def sha256_params(obj: Any) -> str:
    """Hex sha256 of the canonical JSON of ``obj`` (key order does not matter)."""
    return sha256_bytes(canonical_json(obj).encode("utf-8"))


def content_digest(attrs: Mapping[str, AttrValue], data: Mapping[str, np.ndarray]) -> str:
    """Hex sha256 of an artefact's contents: its caller attributes (canonical JSON) and
    each dataset by sorted name (name, dtype, shape, little-endian bytes; strings as
    JSON).  The same before writing and after reading."""
    h = hashlib.sha256(canonical_json(dict(attrs)).encode("utf-8"))
    for name in sorted(data):
        arr = np.asarray(data[name])
        if arr.dtype.kind in "OUS":
            kind, payload = "str", json.dumps([str(x) for x in arr.ravel().tolist()]).encode("utf-8")
        else:
            a = np.ascontiguousarray(arr, dtype=arr.dtype.newbyteorder("<"))
            kind, payload = a.dtype.str, a.tobytes()
        h.update(f"{name}\0{kind}\0{arr.shape}\0{len(payload)}\0".encode("utf-8"))
        h.update(payload)
    return h.hexdigest()


def robot_identity(robot) -> str:
    """A short name of a robot for artefact file names, e.g. ``baxter-1a2b3c4d``: the
    robot.yaml's folder (its file stem when it is not called ``robot.yaml``) and 8 hex
    digits of the SHA-256 of the URDF and the hands (``robot.spec.hands``, the part of the
    robot.yaml a grasp depends on).  Two robots sharing a cache get different names, so
    neither overwrites the other's artefacts; the provenance inside still decides whether
    a file is fresh.  ``robot``: a loaded :class:`~regrasp_cli.model.robot.Robot` (its
    ``spec.file``, ``spec.hands`` and ``urdf_sha256`` are read)."""
    hands = {side: repr(spec) for side, spec in sorted(robot.spec.hands.items())}  # repr: any field type
    digest = sha256_params({"urdf": robot.urdf_sha256, "hands": hands})[:8]
    return f"{robot_label(robot)}-{digest}"


def robot_label(robot) -> str:
    """A robot's readable name in artefact file names: its robot.yaml's folder (its file
    stem when it is not called ``robot.yaml``), e.g. ``baxter``."""
    file = Path(robot.spec.file)
    return file_label(file.parent.name if file.name == "robot.yaml" and file.parent.name else file.stem)


def file_label(name: str) -> str:
    """``name`` with every run of characters other than letters, digits, ``_``, ``.``
    and ``-`` replaced by ``_`` (safe in a file name on every system)."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name) or "_"


# ---------------------------------------------------------------------- atomic writes


def check_writable(path: str | Path, field: str | None = None, folder: bool = False,
                   inputs: Iterable[str | Path] = ()) -> None:
    """Refuse, before any work, an output ``path`` (a file, or a ``folder``) that cannot
    be written: one of the command's ``inputs`` (the same file by its device and inode,
    whatever the path, link or case that names it), a folder where a file is expected or
    the reverse, a missing parent that cannot be created (a file in the way), or a folder
    where no file can be created (probed by creating one: permission bits do not tell,
    e.g. for root).

    Raises:
        InputError: naming ``field`` (e.g. the command-line option) and the reason.
    """
    path = Path(path)
    for source in inputs:
        if _same_file(path, Path(source)):
            raise InputError(None, field, f"{path} is the input file {source} of this command; expected "
                                          f"another file (writing it would overwrite the input)")
    if path.is_dir() and not folder:
        raise InputError(None, field, f"{path} is a folder; expected a file name")
    if path.exists() and folder and not path.is_dir():
        raise InputError(None, field, f"{path} is a file; expected a folder")
    existing = path if folder and path.is_dir() else path.parent
    while not existing.exists():  # missing folders are created on writing
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(None, field, f"cannot create {path}: {existing} is a file, not a folder")
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        raise InputError(None, field, f"cannot write {path}: {existing} is not writable "
                                      f"({exc.strerror or exc})") from None


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # either is missing: an output not yet written overwrites nothing
        return False


def atomic_write(path: str | Path, writer: Callable[[Path], None]) -> None:
    """Create ``path`` atomically: ``writer(tmp)`` fills ``.<name>.<host>.<pid>.tmp``
    beside it, which is fsynced and moved into place with ``os.replace``.

    The parent directory is created.  If anything fails the temp file is removed, the
    previous ``path`` (if any) is left untouched, and the exception is re-raised; an
    operating-system error (no permission, disk full, a file in the way) as an
    :class:`InputError` naming ``path``.  Temp files of ``path`` left by a writer of this
    host that was killed (its process is gone) are removed first.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{_HOST}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        _remove_orphans(path)
        tmp.unlink(missing_ok=True)
        writer(tmp)
        fd = os.open(tmp, os.O_RDONLY | getattr(os, "O_BINARY", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError as exc:
        _remove(tmp)
        raise InputError(path, None, f"cannot write the file: {exc.strerror or exc}") from None
    except BaseException:
        _remove(tmp)
        raise
    _fsync_dir(path.parent)


_HOST = socket.gethostname().replace(".", "-") or "host"  # a shared cache's writers on other hosts are left alone


def _remove_orphans(path: Path) -> None:
    """Remove ``path``'s temp files whose writer, a process of this host, is gone."""
    prefix = f".{path.name}.{_HOST}."
    for tmp in path.parent.glob(f".{glob.escape(path.name)}.*.tmp"):
        pid = tmp.name[len(prefix):-len(".tmp")] if tmp.name.startswith(prefix) else ""
        if pid.isdigit() and not _alive(int(pid)):
            _remove(tmp)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process: alive
        return True
    return True


def _remove(tmp: Path) -> None:
    try:
        tmp.unlink(missing_ok=True)
    except OSError:
        pass  # e.g. its folder could not be created


def _fsync_dir(directory: Path) -> None:
    """Persist a rename (best effort; POSIX only)."""
    if os.name != "posix":
        return
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Atomically replace ``path`` by ``data``."""

    def writer(tmp: Path) -> None:
        tmp.write_bytes(data)

    atomic_write(path, writer)


def atomic_write_text(path: str | Path, text: str, encoding: str = "utf-8") -> None:
    """Atomically replace ``path`` by ``text``."""
    atomic_write_bytes(path, text.encode(encoding))


# ------------------------------------------------------------------------ provenance


class ExpectedProvenance(Protocol):
    """What a reader expects: the kind, its layout version and the current input hashes."""

    @property
    def format(self) -> str: ...

    @property
    def format_version(self) -> int: ...

    @property
    def inputs(self) -> Mapping[str, str]: ...


@dataclasses.dataclass(frozen=True)
class Provenance:
    """Where an artefact comes from.

    ``inputs`` maps an input name (``"urdf"``, ``"robot_yaml"``, ``"mesh"``,
    ``"params"``, ...) to its sha256 hex.  ``software_version`` and ``created`` are
    left empty by callers and filled by :func:`write_artefact`.
    """

    format: str
    format_version: int
    inputs: Mapping[str, str] = dataclasses.field(default_factory=dict, hash=False)
    software_version: str = ""
    created: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.format, str) or not self.format:
            raise ValueError(f"Provenance.format must be a non-empty str, got {self.format!r}")
        if isinstance(self.format_version, bool) or not isinstance(self.format_version, int):
            raise ValueError(f"Provenance.format_version must be an int, got {self.format_version!r}")
        for name, digest in self.inputs.items():
            if not isinstance(name, str) or not name or not isinstance(digest, str):
                raise ValueError(f"Provenance.inputs: bad entry {name!r}: {digest!r}")
        object.__setattr__(self, "inputs", dict(sorted(self.inputs.items())))


def _utc_now() -> str:
    return datetime.now(timezone.utc).replace(microsecond=0).isoformat().replace("+00:00", "Z")


def _rebuild_hint(fmt: str) -> str:
    """``"regrasp.grasps"`` -> ``"regrasp grasps build"``."""
    kind = fmt.removeprefix("regrasp.").replace(".", " ")
    return f"regrasp {kind} build"


# ------------------------------------------------------------------------- artefacts


@dataclasses.dataclass(frozen=True, eq=False)
class Artefact:
    """A loaded artefact: its provenance, caller attributes and every dataset.

    ``data`` keys are full paths without the leading slash, e.g.
    ``"grasps/hand_in_object"``; ``artefact[name]`` is ``data[name]`` but raises an
    :class:`InputError` naming the file and dataset when it is absent.
    """

    path: Path
    provenance: Provenance
    attrs: dict[str, AttrValue]
    data: dict[str, np.ndarray]

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[name]
        except KeyError:
            have = ", ".join(sorted(self.data)) or "none"
            raise InputError(self.path, name, f"artefact has no dataset '{name}' (has: {have})") from None


def _check_name(name: str, what: str) -> None:
    if not isinstance(name, str) or not name or name.startswith("/") or name.endswith("/") or "//" in name:
        raise ValueError(f"write_artefact: bad {what} name {name!r}")


def _as_storable(name: str, value: Any) -> tuple[np.ndarray, Any]:
    arr = np.asarray(value)
    if arr.dtype.kind == "U":
        return arr.astype(object), h5py.string_dtype("utf-8")
    if arr.dtype.kind not in "biufc":
        raise TypeError(f"write_artefact: dataset {name!r} has unsupported dtype {arr.dtype}")
    return arr, arr.dtype


@contextmanager
def artefact_lock(path: str | Path, create: bool = True) -> Iterator[None]:
    """Hold the inter-process lock of one artefact (``<path>.lock`` beside it): taken to
    write it, and by a reader from its freshness check to its hash, so that two runs on
    one cache build it once and a plan's recorded hash is the file it used.  Re-entrant
    in one thread.  In a folder where no lock file can be made (a read-only cache),
    nobody can write the artefact either, so there is nothing to wait for; without
    ``create``, a missing folder is not created (a reader that will not build)."""
    path = Path(path)
    try:
        if create:
            path.parent.mkdir(parents=True, exist_ok=True)
        elif not path.parent.is_dir():
            raise FileNotFoundError(path.parent)
        lock = FileLock(str(path.with_name(path.name + ".lock")), is_singleton=True)
        lock.acquire()
    except OSError:
        yield
        return
    try:
        yield
    finally:
        lock.release()


def write_artefact(
    path: str | Path,
    provenance: Provenance,
    datasets: Mapping[str, np.ndarray],
    attrs: Mapping[str, AttrValue] | None = None,
    groups: Mapping[str, Mapping[str, np.ndarray]] | None = None,
) -> Provenance:
    """Atomically write one HDF5 artefact (layout in the module docstring).

    Empty ``software_version``/``created`` fields of ``provenance`` are filled with
    ``regrasp_cli.__version__`` and the current UTC time.  Dataset names may contain
    ``/``; ``groups`` maps a group path to its datasets.  Numeric, bool and unicode
    string arrays are supported.  Returns the provenance actually written.
    """
    prov = dataclasses.replace(
        provenance,
        software_version=provenance.software_version or __version__,
        created=provenance.created or _utc_now(),
    )
    user_attrs = dict(attrs or {})
    for key, val in user_attrs.items():
        if not isinstance(key, str) or not key or key in _PROVENANCE_ATTRS or key.startswith(INPUT_PREFIX):
            raise ValueError(f"write_artefact: attribute name {key!r} is reserved or invalid")
        if isinstance(val, bool) or not isinstance(val, (str, int, float)):
            raise TypeError(f"write_artefact: attribute {key!r} must be str, int or float, got {val!r}")

    flat: dict[str, Any] = {}
    for name, arr in datasets.items():
        _check_name(name, "dataset")
        flat[name] = arr
    for gname, members in (groups or {}).items():
        _check_name(gname, "group")
        for name, arr in members.items():
            _check_name(name, "dataset")
            full = f"{gname}/{name}"
            if full in flat:
                raise ValueError(f"write_artefact: dataset {full!r} given twice")
            flat[full] = arr
    stored = {name: _as_storable(name, arr) for name, arr in sorted(flat.items())}
    digest = content_digest(user_attrs, {name: arr for name, (arr, _) in stored.items()})

    def writer(tmp: Path) -> None:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = prov.format
            f.attrs["format_version"] = prov.format_version
            f.attrs["software_version"] = prov.software_version
            f.attrs["created"] = prov.created
            f.attrs[CHECKSUM_ATTR] = digest
            for name, input_digest in prov.inputs.items():
                f.attrs[INPUT_PREFIX + name] = input_digest
            for key, val in sorted(user_attrs.items()):
                f.attrs[key] = val
            for name, (arr, dtype) in stored.items():
                f.create_dataset(name, data=arr, dtype=dtype, track_times=False)

    with artefact_lock(path):
        atomic_write(path, writer)
    return prov


def _damaged(path: Path, what: str, hint: str | None) -> CorruptArtefactError:
    fix = f"rebuild it with `{hint}`" if hint else "delete it and build it again"
    return CorruptArtefactError(path, None, f"damaged artefact: {what}; {fix}")


@contextmanager
def _open(path: Path, hint: str | None = None) -> Iterator[h5py.File]:
    """Open an artefact read-only; h5py failures become one-line errors (a file that
    cannot be read is damaged: :class:`CorruptArtefactError`)."""
    if not path.exists():
        fix = f"; build it with `{hint}`" if hint else ""
        raise InputError(path, None, f"no such artefact (file does not exist){fix}")
    if path.is_dir():
        raise InputError(path, None, "expected an artefact file, found a folder")
    try:
        f = h5py.File(path, "r")
    except (OSError, ValueError, RuntimeError) as e:
        size = path.stat().st_size
        what = "the file is empty" if size == 0 else f"not a readable HDF5 file, {size} bytes (truncated?): {e}"
        raise _damaged(path, what, hint) from None
    try:
        with f:
            yield f
    except (OSError, ValueError, RuntimeError, KeyError) as e:
        raise _damaged(path, f"HDF5 cannot read it ({' '.join(str(e).split())})", hint) from None


def _plain(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode("utf-8")
    if isinstance(value, np.generic):
        return value.item()
    return value


def _provenance_of(path: Path, f: h5py.File) -> Provenance:
    attrs = f.attrs
    fmt = _plain(attrs.get("format"))
    version = _plain(attrs.get("format_version"))
    if not isinstance(fmt, str):
        raise InputError(path, "format", "not a regrasp artefact (no 'format' attribute)")
    if isinstance(version, bool) or not isinstance(version, int):
        raise InputError(path, "format_version", f"not a regrasp artefact (format_version is {version!r})")
    inputs = {k[len(INPUT_PREFIX):]: str(_plain(v)) for k, v in attrs.items() if k.startswith(INPUT_PREFIX)}
    return Provenance(
        format=fmt,
        format_version=version,
        inputs=inputs,
        software_version=str(_plain(attrs.get("software_version", ""))),
        created=str(_plain(attrs.get("created", ""))),
    )


def _short(digest: str | None) -> str:
    return "none" if digest is None else digest[:12] + "…"


def _check(path: Path, found: Provenance, expected: ExpectedProvenance, hint: str) -> None:
    """Refuse ``found`` unless it matches ``expected`` (see the module docstring)."""
    if found.format != expected.format:
        raise InputError(path, "format", f"expected '{expected.format}', found '{found.format}'")
    if found.format_version < expected.format_version:
        raise StaleArtefactError(
            path,
            "format_version",
            f"expected format version {expected.format_version}, found {found.format_version} "
            f"(written by regrasp {found.software_version or '?'}); rebuild it with `{hint}`",
        )
    if found.format_version > expected.format_version:
        raise InputError(
            path,
            "format_version",
            f"expected format version {expected.format_version}, found {found.format_version}: "
            f"written by a newer regrasp ({found.software_version or '?'}); "
            f"upgrade regrasp or rebuild it with `{hint}`",
        )
    problems: list[tuple[str, str]] = []
    for name in sorted(set(found.inputs) | set(expected.inputs)):
        stored, current = found.inputs.get(name), expected.inputs.get(name)
        if stored == current:
            continue
        if stored is None:
            problems.append((name, f"was built without a {name} input"))
        elif current is None:
            problems.append((name, f"was built with a {name} input that is no longer used"))
        else:
            problems.append((name, f"was built for a different {name} (stored {_short(stored)}, current {_short(current)})"))
    if problems:
        reasons = "; ".join(reason for _, reason in problems)
        raise StaleArtefactError(path, INPUT_PREFIX + problems[0][0], f"{reasons}; rebuild it with `{hint}`")


def read_provenance(path: str | Path) -> Provenance:
    """The provenance recorded in an artefact, without checking it (for ``show`` commands)."""
    path = Path(path)
    with _open(path) as f:
        return _provenance_of(path, f)


def read_artefact(path: str | Path, expected: ExpectedProvenance, rebuild: str | None = None) -> Artefact:
    """Load an artefact after checking its format, version and input hashes.

    ``rebuild`` is the command quoted in refusals (default: ``regrasp <kind> build``
    from ``expected.format``).  Raises :class:`InputError` for a missing, unreadable or
    foreign file and :class:`StaleArtefactError` naming every mismatching input.
    """
    path = Path(path)
    hint = rebuild or _rebuild_hint(expected.format)
    with _open(path, hint) as f:
        prov = _provenance_of(path, f)
        _check(path, prov, expected, hint)
        attrs = {
            k: _plain(v) for k, v in f.attrs.items() if k not in _PROVENANCE_ATTRS and not k.startswith(INPUT_PREFIX)
        }
        data: dict[str, np.ndarray] = {}

        def visit(name: str, obj: Any) -> None:
            if isinstance(obj, h5py.Dataset):
                if h5py.check_string_dtype(obj.dtype) is not None:
                    data[name] = np.asarray(obj.asstr()[()], dtype=str)
                else:
                    data[name] = np.asarray(obj[()])

        f.visititems(visit)
        stored = _plain(f.attrs.get(CHECKSUM_ATTR))
    if stored is None:
        raise StaleArtefactError(path, CHECKSUM_ATTR, f"written without a content checksum (regrasp "
                                                      f"{prov.software_version or '?'}); rebuild it with `{hint}`")
    if content_digest(attrs, data) != stored:
        raise _damaged(path, "its contents do not match the checksum written with them (bytes changed on disk)",
                       hint)
    return Artefact(path=path, provenance=prov, attrs=attrs, data=data)


def is_fresh(path: str | Path, expected: ExpectedProvenance) -> bool:
    """``True`` if ``path`` exists, matches ``expected`` and its contents match their
    checksum; ``False`` if missing, stale or damaged (see :func:`why_not_fresh`).

    Other refusals (different ``format``, newer ``format_version``) still raise
    :class:`InputError`: rebuilding would overwrite something unexpected.
    """
    return why_not_fresh(path, expected) is None


def why_not_fresh(path: str | Path, expected: ExpectedProvenance) -> str | None:
    """None for an artefact :func:`is_fresh` accepts; else why it must be (re)built, in
    a few words ("missing", or the stale or damage message).  The whole file is read."""
    path = Path(path)
    if not path.exists():
        return "missing"
    try:
        read_artefact(path, expected)
    except StaleArtefactError as exc:
        return exc.message
    return None
