"""The examples in the docstrings run and print what they say."""

import doctest

import pytest

import hamsa.eigen
import hamsa.factorization
import hamsa.mesh


@pytest.mark.parametrize("module", [hamsa.eigen, hamsa.mesh, hamsa.factorization], ids=lambda m: m.__name__)
def test_docstring_examples(module):
    result = doctest.testmod(module)
    assert result.attempted > 0 and result.failed == 0
