"""What hamsa runs on here: versions, the sparse factorization and the BLAS behind it, threads, a GPU.

``hamsa.show_config()`` (and ``hamsa config`` on the command line) prints it; ``configuration()`` returns
it as a dict for scripts and bug reports. The BLAS matters for CHOLMOD's supernodal kernel (the default
of ``sksparse.cholmod.cholesky``, e.g. in the eigsh + CHOLMOD baseline, and hamsa's own from
:data:`hamsa.factorization.SUPERNODAL_FROM` rows): Debian's CHOLMOD uses whichever ``libblas.so.3`` the
system selects — the slow reference BLAS unless an optimized one (e.g. ``libopenblas0-pthread``, which
``make`` installs when it can) is there.
"""

from __future__ import annotations

import os
import platform
from pathlib import Path

from hamsa import __version__

_BLAS_NAMES = (("openblas", "OpenBLAS"), ("mkl", "Intel MKL"), ("blis", "BLIS"), ("atlas", "ATLAS"))


def blas_kind(path: str) -> str:
    """The BLAS implementation a shared-library path is (after resolving links): OpenBLAS, Intel MKL, BLIS,
    ATLAS, or the reference (netlib) BLAS for a plain ``libblas``."""
    resolved = os.path.realpath(path).lower()
    for key, name in _BLAS_NAMES:
        if key in resolved:
            return name
    return "reference BLAS (netlib, unoptimized)" if "libblas" in Path(resolved).name else "unknown"


def _loaded_blas() -> list[str]:
    """The BLAS shared libraries this process has loaded (Linux: /proc/self/maps), links resolved."""
    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return []
    libraries = {line.split()[-1] for line in maps.splitlines() if line.count(" ") >= 5 and "/" in line}
    wanted = ("blas", "mkl_rt", "blis")  # libblas, lib(scipy_)openblas, libcblas, libsatlas, MKL, BLIS
    names = {p: Path(p).name for p in libraries}
    return sorted(
        {os.path.realpath(p) for p, name in names.items() if name.startswith("lib") and any(w in name for w in wanted)}
    )


def _numpy_blas() -> str:
    import numpy as np

    try:
        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        return f"{blas.get('name', '?')} {blas.get('version', '')}".strip()
    except Exception:  # older numpy: no machine-readable configuration
        return "unknown"


def configuration() -> dict:
    """Versions, the factorization ``backend="auto"`` picks, the BLAS libraries loaded (numpy's and the one
    CHOLMOD uses), thread settings, and whether a CUDA GPU with CuPy is there."""
    import numpy as np
    import scipy

    from hamsa.factorization import HAVE_CHOLMOD

    config = {
        "hamsa": __version__,
        "python": platform.python_version(),
        "platform": platform.platform(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numpy_blas": _numpy_blas(),
        "factorization": _factorization(),
    }
    if HAVE_CHOLMOD:
        import sksparse

        config["scikit_sparse"] = getattr(sksparse, "__version__", "?")
    loaded = _loaded_blas()
    config["blas_loaded"] = [f"{blas_kind(p)}: {p}" for p in loaded]
    system = [p for p in loaded if Path(p).name.startswith("libblas")]  # what Debian's CHOLMOD links
    if HAVE_CHOLMOD:
        config["cholmod_blas"] = blas_kind(system[0]) if system else "not found among the loaded libraries"
    config["cpus"] = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    config["threads"] = {
        name: os.environ[name]
        for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
        if name in os.environ
    } or "not set (the BLAS libraries choose)"
    config["gpu"] = _gpu()
    return config


def _factorization() -> str:
    """The sparse factorization ``backend="auto"`` uses, and its kernel by size."""
    from hamsa.factorization import HAVE_CHOLMOD, SUPERNODAL_FROM, cholmod_thread_pools

    if not HAVE_CHOLMOD:
        return "SciPy SuperLU (install hamsa[fast] for CHOLMOD)"
    if cholmod_thread_pools() is None:
        return "CHOLMOD (scikit-sparse), simplicial LDL^T, METIS ordering (no optimized BLAS behind it)"
    return (
        f"CHOLMOD (scikit-sparse), METIS ordering: simplicial LDL^T below {SUPERNODAL_FROM:,} rows, "
        "supernodal LL^T from there (its solves on one BLAS thread)"
    )


def _gpu() -> str:
    try:
        import cupy
    except ImportError:
        return "no CuPy (device='cuda' needs hamsa[gpu-cuda12] or [gpu-cuda13])"
    try:
        properties = cupy.cuda.runtime.getDeviceProperties(0)
        return f"{properties['name'].decode()} (CuPy {cupy.__version__})"
    except Exception as error:  # CuPy installed, no usable device
        return f"CuPy {cupy.__version__}, no usable CUDA device ({type(error).__name__})"


def show_config() -> dict:
    """Print :func:`configuration` one line per item and return it."""
    config = configuration()
    for key, value in config.items():
        if isinstance(value, list):
            print(f"{key:<16}{value[0] if value else 'none'}")
            for item in value[1:]:
                print(f"{'':<16}{item}")
        elif isinstance(value, dict):
            print(f"{key:<16}{', '.join(f'{k}={v}' for k, v in value.items())}")
        else:
            print(f"{key:<16}{value}")
    return config
