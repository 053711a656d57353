"""The examples in the public modules' docstrings run and give what they show."""

import doctest

import affcorr.solvers
import pytest


@pytest.mark.parametrize("module", [affcorr.solvers])
def test_docstring_examples(module):
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0


def test_solvers_namespace_matches_the_top_level():
    for name in affcorr.solvers.__all__:
        assert getattr(affcorr.solvers, name) is getattr(affcorr, name)
