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
