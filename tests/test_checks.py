"""embodied_adhoc.checks: user values are accepted in their canonical type or refused with one ConfigError."""

import math

import numpy as np
import pytest

from embodied_adhoc import checks
from embodied_adhoc.errors import ConfigError


@pytest.mark.parametrize(
    "value", [3, np.int8(3), np.uint64(3), np.int32(3), np.array(3), np.array(3, np.uint16)]
)
def test_integers_of_any_width_are_accepted(value):
    result = checks.integer("k", value, 0, 4)
    assert result == 3 and type(result) is int


@pytest.mark.parametrize(
    "value", [3.0, 2.7, "3", None, True, np.bool_(True), np.array([3]), np.float64(3.0), np.array(3.0), [3]]
)
def test_everything_else_is_refused_with_the_name(value):
    with pytest.raises(ConfigError, match=r"^k=.*must be an integer in 0\.\.4"):
        checks.integer("k", value, 0, 4)


def test_ranges_are_named():
    with pytest.raises(ConfigError, match=r"k=5: outside 0\.\.4"):
        checks.integer("k", 5, 0, 4)
    with pytest.raises(ConfigError, match=r"k=0: must be >= 1"):
        checks.integer("k", 0, 1)


def test_numbers_flags_choices():
    assert checks.number("p", 1, 0.0, 1.0) == 1.0 and checks.number("p", np.float32(0.5), 0.0, 1.0) == 0.5
    for bad in ("0.5", True, None, math.nan, math.inf, 1.5, -0.1):
        with pytest.raises(ConfigError, match="p="):
            checks.number("p", bad, 0.0, 1.0)
    with pytest.raises(ConfigError, match=r"\(0\.0, inf\]"):
        checks.number("t", 0.0, 0.0, low_open=True)
    assert checks.flag("f", np.bool_(True)) is True
    for bad in ("no", 0, 1, None):
        with pytest.raises(ConfigError, match="True or False"):
            checks.flag("f", bad)
    assert checks.choice("c", "fast", ("fast", "high")) == "fast"
    for bad in ("slow", True, np.array(["fast"]), None):
        with pytest.raises(ConfigError, match="use one of 'fast', 'high'"):
            checks.choice("c", bad, ("fast", "high"))


def test_unknown_names_get_a_suggestion():
    checks.refuse_unknown("env", {"rows": 5}, ("rows", "cols"))
    with pytest.raises(
        ConfigError, match=r"env: unknown keyword 'rowz' \(did you mean 'rows'\?\); accepted: rows, cols"
    ):
        checks.refuse_unknown("env", {"rowz": 5}, ("rows", "cols"))
    with pytest.raises(ConfigError, match="unknown options 'a', 'b'"):
        checks.refuse_unknown("reset options", {"b": 1, "a": 2}, ("task",), what="option")
