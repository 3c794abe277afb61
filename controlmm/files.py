"""Reading the user's input files: one-line errors that name the file and what was expected.

* :func:`input_file` / :func:`input_dir` - the path exists and is a file (a directory).
* :func:`load_array` - a ``.npy`` array or the arrays of a ``.npz`` archive, never unpickled:
  a file that is not a valid NPY/NPZ is "not a valid NPZ file", without numpy's advice to
  allow pickles (loading pickles runs code from the file).
* :func:`load_pickle` - a pickle of plain data (numbers, strings, lists, dicts, numpy arrays) read
  by a restricted unpickler: a pickle can name any Python callable to run while it loads, so only
  numpy's array and dtype constructors and builtin containers are allowed, anything else refused.
"""

from __future__ import annotations

import io
import os
import pickle
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from controlmm.errors import InputFileError


def input_file(path: str | os.PathLike[str], what: str = "file") -> Path:
    """``path`` as a Path if it is an existing file; else a one-line InputFileError."""
    path = Path(path).expanduser()
    if path.is_dir():
        raise InputFileError(f"{what} '{path}' is a directory; expected a file")
    if not path.is_file():
        raise InputFileError(f"{what} '{path}' does not exist")
    return path


def input_dir(path: str | os.PathLike[str], what: str = "directory") -> Path:
    """``path`` as a Path if it is an existing directory; else a one-line InputFileError."""
    path = Path(path).expanduser()
    if path.exists() and not path.is_dir():
        raise InputFileError(f"{what} '{path}' is a file; expected a directory")
    if not path.is_dir():
        raise InputFileError(f"{what} '{path}' does not exist")
    return path


def load_array(path: str | os.PathLike[str], what: str = "file") -> np.ndarray | dict[str, np.ndarray]:
    """The array of a ``.npy`` file, or ``{name: array}`` of a ``.npz`` archive (read eagerly).

    Object (pickled) arrays are refused: a one-line InputFileError says the file is not a
    valid NPY/NPZ file.
    """
    path = input_file(path, what)
    kind = "NPZ" if path.suffix.lower() == ".npz" else "NPY"
    with open(path, "rb") as fh:
        magic = fh.read(6)
    if not magic.startswith((b"PK\x03\x04", b"PK\x05\x06", b"\x93NUMPY")):
        raise InputFileError(f"{what} '{path}' is not a valid {kind} file")
    try:
        data = np.load(path, allow_pickle=False)
        if isinstance(data, np.lib.npyio.NpzFile):
            with data:
                return {name: data[name] for name in data.files}
        return np.asarray(data)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        reason = "it holds pickled objects, which are never loaded" if "pickle" in str(exc) else str(exc)
        raise InputFileError(f"{what} '{path}' is not a valid {kind} file ({reason})") from None


def load_torch(path: str | os.PathLike[str], what: str = "checkpoint", hint: str = "") -> Any:
    """``torch.load(path, weights_only=True)`` on the CPU with one-line errors.

    Only tensors and plain containers are ever loaded (never arbitrary pickled objects). A
    file that is not a ``torch.save`` file, is truncated, or holds other Python objects gets
    "not a valid checkpoint" naming it, followed by ``hint`` (how to recover) when given.
    """
    import torch  # heavy: only the commands that read checkpoints pay for it

    path = input_file(path, what)
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - corrupt, truncated or unsafe pickles raise many types
        if "weights only" in str(exc).lower() and zipfile.is_zipfile(path):
            reason = "it holds Python objects besides tensors, which are never unpickled here"
        elif zipfile.is_zipfile(path):
            reason = f"corrupt or truncated: {type(exc).__name__}"
        else:
            reason = "not a file written by torch.save"
        raise InputFileError(
            f"{what} '{path}' is not a valid checkpoint ({reason}){'; ' + hint if hint else ''}"
        ) from None


_PICKLE_GLOBALS = frozenset(
    [(m, "_reconstruct") for m in ("numpy.core.multiarray", "numpy._core.multiarray")]
    + [(m, "scalar") for m in ("numpy.core.multiarray", "numpy._core.multiarray")]
    + [(m, "_frombuffer") for m in ("numpy.core.numeric", "numpy._core.numeric")]
    + [("numpy", "ndarray"), ("numpy", "dtype"), ("_codecs", "encode"), ("collections", "OrderedDict")]
    + [
        ("builtins", n)
        for n in ("dict", "list", "tuple", "set", "frozenset", "bytes", "bytearray", "str", "int", "float")
        + ("complex", "bool", "slice", "range")
    ]
)
"""(module, name) pairs a pickle may construct: numpy arrays, dtypes and scalars, builtin containers."""


class _NotPlainData(pickle.UnpicklingError):
    """A pickle asked for a global outside :data:`_PICKLE_GLOBALS`."""


class _PlainDataUnpickler(pickle.Unpickler):
    """An unpickler that refuses every global outside :data:`_PICKLE_GLOBALS`."""

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) in _PICKLE_GLOBALS or (module == "numpy.dtypes" and name.endswith("DType")):
            return super().find_class(module, name)
        raise _NotPlainData(f"it names '{module}.{name}', which is not plain data")


def load_pickle(path: str | os.PathLike[str], what: str = "file") -> Any:
    """The object of a pickle holding plain data only (numbers, strings, containers, numpy arrays).

    A pickle may run any Python code while it loads; this reader allows only numpy's array, dtype
    and scalar constructors and builtin containers (:data:`_PICKLE_GLOBALS`) and refuses the file
    with a one-line InputFileError naming whatever else it asks for.
    """
    path = input_file(path, what)
    try:
        with open(path, "rb") as fh:
            return _PlainDataUnpickler(io.BytesIO(fh.read())).load()
    except _NotPlainData as exc:
        raise InputFileError(
            f"{what} '{path}' is refused: {exc} (a pickle can run code as it loads)"
        ) from None
    except (
        pickle.UnpicklingError,
        EOFError,
        ValueError,
        TypeError,
        AttributeError,
        IndexError,
        KeyError,
        MemoryError,
    ) as exc:
        raise InputFileError(f"{what} '{path}' is not a valid pickle ({type(exc).__name__})") from None
