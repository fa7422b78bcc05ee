"""Reading ``.npz`` array files safely: sizes and headers checked before allocating."""

from __future__ import annotations

import math
import os
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["read_npz"]


def read_npz(arr_path: str | os.PathLike, *, max_arrays: int = 4096,
             max_bytes: int = 1 << 30) -> dict[str, np.ndarray]:
    """Read an ``.npz`` of numeric arrays, checking it before anything is allocated.

    At most ``max_arrays`` members; every member a ``.npy`` whose header
    (dtype numeric, shape) matches the bytes stored; in total at most
    ``min(max_bytes, 64 * file size + 16 MiB)`` bytes of arrays. No pickle.

    Raises
    ------
    ValueError
        Naming the file and the problem.

    Examples
    --------
    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "a.npz"
    >>> np.savez(p, x=np.arange(3.0))
    >>> read_npz(p)["x"].tolist()
    [0.0, 1.0, 2.0]
    """
    arr_path = Path(arr_path)
    file_bytes = arr_path.stat().st_size
    budget = min(max_bytes, 64 * file_bytes + (16 << 20))
    where = str(arr_path)
    try:
        with zipfile.ZipFile(arr_path) as zf:
            infos = zf.infolist()
            if len(infos) > max_arrays:
                raise ValueError(f"{where!r} holds {len(infos)} arrays, more than the limit "
                                 f"{max_arrays}")
            total = 0
            for info in infos:
                if not info.filename.endswith(".npy"):
                    raise ValueError(f"{where!r} holds a member {info.filename!r} that is not "
                                     "a .npy array")
                total += info.file_size
                if total > budget:
                    raise ValueError(f"{where!r} claims {total} bytes of arrays, more than "
                                     f"the limit {budget} for a file of {file_bytes} bytes")
                with zf.open(info) as fh:
                    version = np.lib.format.read_magic(fh)
                    if version not in ((1, 0), (2, 0), (3, 0)):
                        raise ValueError(f"unsupported .npy version {version}")
                    read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                            else np.lib.format.read_array_header_2_0)
                    shape, _, dtype = read(fh, max_header_size=10_000)
                    header_len = fh.tell()
                if dtype.hasobject or dtype.kind not in "biuf":
                    raise ValueError(f"{where!r}: array {info.filename[:-4]!r} has dtype "
                                     f"{dtype}; only numeric arrays are read")
                nbytes = math.prod(int(n) for n in shape) * dtype.itemsize
                if nbytes != info.file_size - header_len:
                    raise ValueError(f"{where!r}: array {info.filename[:-4]!r} claims shape "
                                     f"{shape} ({nbytes} bytes) but stores "
                                     f"{info.file_size - header_len} bytes")
        with np.load(arr_path, allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except ValueError as exc:
        if where in str(exc):
            raise
        raise ValueError(f"{where!r} could not be read as a .npz array file: {exc}") from exc
    except (OSError, EOFError, KeyError, zipfile.BadZipFile, NotImplementedError,
            RuntimeError, OverflowError, SyntaxError, TypeError) as exc:
        raise ValueError(f"{where!r} could not be read as a .npz array file: "
                         f"{type(exc).__name__}: {exc}") from exc
