"""Which array library the batch engine runs on: numpy on the CPU, CuPy on a GPU.

The engine is written against the Python array API standard (https://data-apis.org/array-api/),
through ``array_api_compat``'s namespaces, so the same code runs on numpy arrays (the default,
and what every test covers) and on CuPy arrays (``device="gpu"``, when CuPy and a GPU are
present). Nothing else in the project needs CuPy.
"""

from __future__ import annotations

import numpy as np

#: The devices the engine knows: ``cpu`` (numpy) and ``gpu`` (CuPy).
DEVICES = ("cpu", "gpu")
#: Not a device: the standard's strict reference library (``array-api-strict``, a test dependency),
#: which refuses anything outside the standard; the tests run the engine on it to show that the
#: GPU path uses nothing numpy has and CuPy might not.
STRICT = "array-api-strict"


def namespace(device: str = "cpu"):
    """The array namespace of ``device`` ("cpu": numpy; "gpu": CuPy on the current GPU).

    Raises ValueError naming the device and the allowed ones, or when the GPU path is asked for
    and CuPy or a GPU is missing.
    """
    if device == "cpu":
        if hasattr(np, "__array_api_version__"):  # numpy 2 follows the standard itself
            return np
        from array_api_compat import numpy as xp
        return xp
    if device == "gpu":
        try:
            import cupy
            count = cupy.cuda.runtime.getDeviceCount()
        except Exception as error:  # ImportError, or CUDA's own error without a driver
            raise ValueError(f"device = 'gpu': CuPy with a CUDA GPU is needed ({type(error).__name__}: {error}); "
                             "allowed devices here: 'cpu'") from None
        if count < 1:
            raise ValueError("device = 'gpu': CuPy finds no GPU; allowed devices here: 'cpu'")
        from array_api_compat import cupy as xp
        return xp
    if device == STRICT:
        import array_api_strict as xp
        return xp
    raise ValueError(f"device = {device!r} is not known; allowed values {DEVICES}")


def to_numpy(x) -> np.ndarray:
    """A host numpy copy of an array of any of the engine's namespaces."""
    if isinstance(x, np.ndarray):
        return x
    get = getattr(x, "get", None)  # CuPy
    if get is not None:
        return get()
    return np.from_dlpack(x)

