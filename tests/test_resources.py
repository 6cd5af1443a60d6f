"""Requests that cannot fit in memory fail early with a ResourceError saying how much they need."""

import pytest

import hamsa
from hamsa import resources, shapes
from hamsa.errors import ResourceError


def test_available_memory_is_read_on_linux():
    available = resources.available_memory()
    assert available is None or available > 1e8


def test_a_request_larger_than_memory_is_refused_before_allocating(monkeypatch):
    monkeypatch.setattr(resources, "available_memory", lambda: 10_000_000)  # pretend 10 MB are free
    mesh = shapes.sphere(3000)
    with pytest.raises(ResourceError, match="GB"):
        hamsa.eigenbasis(mesh, 200, method="krylov")
    with pytest.raises(ResourceError, match="dense eigensolve"):
        hamsa.eigenbasis(mesh, 10, method="dense")
    assert isinstance(ResourceError("x"), hamsa.HamsaError)


def test_the_configuration_names_the_factorization_and_the_blas_behind_it(tmp_path, capsys):
    from hamsa.cli import main
    from hamsa.factorization import HAVE_CHOLMOD
    from hamsa.runtime import blas_kind, configuration

    config = configuration()
    assert config["hamsa"] == hamsa.__version__ and config["cpus"] >= 1
    assert config["factorization"].startswith("CHOLMOD" if HAVE_CHOLMOD else "SciPy SuperLU")
    assert all(": /" in line for line in config["blas_loaded"])
    if HAVE_CHOLMOD:
        assert config["cholmod_blas"]
    (tmp_path / "libopenblas.so.0").write_bytes(b"")
    (tmp_path / "libblas.so.3").symlink_to(tmp_path / "libopenblas.so.0")  # Debian's alternatives: a link
    assert blas_kind(str(tmp_path / "libblas.so.3")) == "OpenBLAS"
    assert blas_kind("/usr/lib/x86_64-linux-gnu/blas/libblas.so.3.11.0").startswith("reference BLAS")
    assert blas_kind("/opt/intel/lib/libmkl_rt.so.2") == "Intel MKL"
    assert main(["config"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"hamsa           {hamsa.__version__}") and "factorization" in out
