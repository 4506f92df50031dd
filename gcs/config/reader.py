"""Reading one TOML table at a time: typed keys checked against :data:`~gcs.config.bounds.BOUNDS`, and matrices."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from gcs.config.bounds import bound_for
from gcs.config.sections import Matrix, MatrixSet
from quadrotor.errors import ConfigError
from quadrotor.bounds import OutOfBounds, short_repr

__all__ = ["Reader", "matrix_group"]


class Reader:
    """Takes keys out of one TOML table, then complains about whatever is left.

    Parameters
    ----------
    table : Any
        The table (anything else is a :class:`ConfigError`).
    source : str
        The file, for messages.
    where : str
        The table's dotted key (``""`` for the document).

    Every number is checked against its entry of :data:`~gcs.config.bounds.BOUNDS`
    (a key without an entry cannot be read as a number).
    """

    def __init__(self, table: Any, source: str, where: str) -> None:
        if not isinstance(table, dict):
            raise ConfigError(source, where, f"must be a table, got {short_repr(table)}")
        self.table = dict(table)
        self.source = source
        self.where = where

    def key(self, name: str) -> str:
        """The dotted key of ``name`` in this table."""
        return f"{self.where}.{name}" if self.where else name

    def error(self, name: str, reason: str) -> ConfigError:
        """A :class:`ConfigError` naming ``name`` of this table."""
        return ConfigError(self.source, self.key(name), reason)

    def has(self, name: str) -> bool:
        """Whether the table (still) holds ``name``."""
        return name in self.table

    def raw(self, name: str, default: Any = ...) -> Any:
        """Take ``name`` out of the table as it is (``default`` when absent; missing without one)."""
        if name in self.table:
            return self.table.pop(name)
        if default is ...:
            raise self.error(name, "missing")
        return default

    def check(self, name: str, value: Any) -> float | int:
        """``value`` checked against the bound of ``name`` (an element of a vector or matrix, too)."""
        try:
            return bound_for(self.key(name)).check(value)
        except OutOfBounds as exc:
            raise self.error(name, str(exc)) from None

    def number(self, name: str, default: Any = ...) -> float:
        """A finite float within its bound; ``default`` (not checked) when absent."""
        if name not in self.table and default is not ...:
            return default
        return float(self.check(name, self.raw(name)))

    def integer(self, name: str, default: Any = ...) -> int:
        """An integer within its bound; ``default`` (not checked) when absent."""
        if name not in self.table and default is not ...:
            return default
        return int(self.check(name, self.raw(name)))

    def vector(self, name: str, default: tuple[float, ...], labels: str) -> tuple[float, ...]:
        """A list of ``len(default)`` numbers within the bound of ``name`` (``labels`` name them in messages)."""
        if name not in self.table:
            return default
        v = self.raw(name)
        if not (isinstance(v, list) and len(v) == len(default)):
            raise self.error(name, f"must be [{labels}], got {short_repr(v)}; {bound_for(self.key(name)).describe()}")
        return tuple(float(self.check(name, x)) for x in v)

    def string(self, name: str, default: Any = ..., *, choices: tuple[str, ...] | None = None) -> str:
        """A string (one of ``choices`` if given)."""
        v = self.raw(name, default)
        if not isinstance(v, str):
            raise self.error(name, f"must be a string, got {short_repr(v)}")
        if choices is not None and v not in choices:
            raise self.error(name, f"must be one of {', '.join(choices)}; got {short_repr(v)}")
        return v

    def boolean(self, name: str, default: Any = ...) -> bool:
        """``true`` or ``false``."""
        v = self.raw(name, default)
        if not isinstance(v, bool):
            raise self.error(name, f"must be true or false, got {short_repr(v)}")
        return v

    def sub(self, name: str, default: Any = ...) -> Reader:
        """A reader of the sub-table ``name``."""
        return Reader(self.raw(name, default), self.source, self.key(name))

    def done(self) -> None:
        """Reject whatever keys are left (unknown keys)."""
        if self.table:
            names = sorted(str(k) for k in self.table)
            raise self.error(names[0], f"unknown key{'s' if len(names) > 1 else ''} ({', '.join(names)})")


# --------------------------------------------------------------------------- matrices

def _matrix(reader: Reader, name: str, n: int) -> Matrix:
    """A number (1x1), a flat list (diagonal) or n rows of n numbers, every entry within its bound."""
    v = reader.raw(name)

    def num(x: Any) -> float:
        if isinstance(x, list):
            raise reader.error(name, f"entries must be numbers, got {short_repr(x)}")
        return float(reader.check(name, x))

    if not isinstance(v, list):
        rows = [[num(v)]]
    elif v and all(not isinstance(r, list) for r in v):
        d = [num(x) for x in v]
        rows = [[d[i] if i == j else 0.0 for j in range(len(d))] for i in range(len(d))]
    elif v and all(isinstance(r, list) for r in v):
        rows = [[num(x) for x in r] for r in v]
    else:
        raise reader.error(name, f"must be a number, a list (diagonal) or a list of rows; got {short_repr(v)}")
    shape = (len(rows), {len(r) for r in rows})
    if shape[0] != n or shape[1] != {n}:
        cols = "/".join(str(c) for c in sorted(shape[1]))
        raise reader.error(name, f"wrong shape: expected {n}x{n}, got {shape[0]}x{cols}")
    return tuple(tuple(r) for r in rows)


def _check_symmetric(reader: Reader, name: str, mat: Matrix, *, definite: bool) -> None:
    a = np.array(mat)
    n = a.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            if not math.isclose(a[i, j], a[j, i], rel_tol=1e-9, abs_tol=1e-12):
                raise reader.error(name, f"not symmetric ({name}[{i + 1},{j + 1}] = {a[i, j]:g} != "
                                         f"{name}[{j + 1},{i + 1}] = {a[j, i]:g})")
    eig = np.linalg.eigvalsh(0.5 * (a + a.T))
    scale = max(1.0, float(np.max(np.abs(eig))))
    if definite and eig.min() <= 1e-12 * scale:
        raise reader.error(name, f"not positive definite (smallest eigenvalue {eig.min():.6g})")
    if not definite and eig.min() < -1e-9 * scale:
        raise reader.error(name, f"indefinite (eigenvalue {eig.min():.6g} < 0); Q and H must be positive semidefinite")


def _matrix_set(reader: Reader, n: int, m: int, mode: str, allow_same_as: tuple[str, ...],
                allow_mirror: bool) -> MatrixSet:
    source = reader.string("source", "")
    note = reader.string("note", "")
    if reader.has("same_as"):
        same_as = reader.string("same_as", choices=allow_same_as)
        if reader.has("mirror") and not allow_mirror:
            raise reader.error("mirror", "only NLSOC mirrors x-theta weights (LOC has the sign in A(2,3))")
        mirror = reader.boolean("mirror", False)
        reader.done()
        # Filled in by the caller from the referenced subsystem.
        return MatrixSet(Q=(), R=(), H=(), source=source, note=note, same_as=same_as, mirror=mirror)
    corrected = reader.raw("corrected", [])
    if not isinstance(corrected, list) or not all(isinstance(c, str) for c in corrected):
        raise reader.error("corrected", f"must be a list of matrix names, got {short_repr(corrected)}")
    dims = {"Q": n, "H": n, "R": m}
    mats = {k: _matrix(reader, k, d) for k, d in dims.items()}
    printed: dict[str, Matrix] = {}
    for k in corrected:
        if k not in dims:
            raise reader.error("corrected", f"unknown matrix {short_repr(k)} (expected Q, R or H)")
        if not reader.has(f"{k}_printed"):
            raise reader.error(f"{k}_printed",
                               f"missing: {k} is listed in 'corrected', so the printed matrix must be given")
        printed[k] = _matrix(reader, f"{k}_printed", dims[k])
    for k in dims:
        if reader.has(f"{k}_printed"):
            raise reader.error(f"{k}_printed", f"given but {k!r} is not listed in 'corrected'")
    reader.done()
    # The printed matrices are flown as printed (erratum 7: they fail these checks by construction);
    # every other matrix is checked in both modes.
    for k in ("Q", "H"):
        if not (mode == "printed" and k in printed):
            _check_symmetric(reader, k, mats[k], definite=False)
    if mode == "printed" and "R" in printed:
        _check_symmetric(reader, "R_printed", printed["R"], definite=True)
    else:
        _check_symmetric(reader, "R", mats["R"], definite=True)
    return MatrixSet(Q=mats["Q"], R=mats["R"], H=mats["H"], source=source, note=note, printed=printed)


def matrix_group(reader: Reader, dims: dict[str, tuple[int, int]], mode: str, *,
                 allow_mirror: bool) -> dict[str, MatrixSet]:
    """``[loc]`` or ``[nlsoc]``: the matrix sets of every subsystem in ``dims`` (``same_as`` resolved).

    Raises
    ------
    ConfigError
        A missing subsystem, a bad matrix (shape, bounds, symmetry, definiteness) or ``same_as``.
    """
    out: dict[str, MatrixSet] = {}
    for name, (n, m) in dims.items():
        others = tuple(k for k in dims if k != name and dims[k] == (n, m))
        out[name] = _matrix_set(reader.sub(name), n, m, mode, others, allow_mirror)
    reader.done()
    for name, ms in out.items():
        if ms.same_as:
            ref = out[ms.same_as]
            if ref.same_as:
                raise reader.error(f"{name}.same_as", f"{ms.same_as!r} is itself defined by same_as")
            out[name] = dataclasses.replace(ref, source=ms.source or ref.source, note=ms.note,
                                            same_as=ms.same_as, mirror=ms.mirror)
    return out
