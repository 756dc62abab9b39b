"""The runnable examples in the engine's and the settling module's docstrings run and hold."""

import doctest

import pytest

import railpaper.engine
import railpaper.engine.changepoint
import railpaper.engine.residual_alarms
import railpaper.settling


@pytest.mark.parametrize("module", [railpaper.engine, railpaper.engine.changepoint,
                                    railpaper.engine.residual_alarms, railpaper.settling])
def test_docstring_example_runs(module):
    result = doctest.testmod(module, raise_on_error=False)
    assert result.attempted >= 3 and result.failed == 0
