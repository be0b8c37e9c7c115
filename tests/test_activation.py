"""Activation curves over time (emu.activation)."""
import numpy as np
import pytest

from emu.core.activation import Curve


def test_curve_interpolations():
    keys = [[0.0, 0.0], [1.0, 1.0], [2.0, 0.5]]
    lin = Curve(keys=keys, interpolation="linear")
    assert lin.value(0, -1.0) == 0.0 and lin.value(0, 5.0) == 0.5
    assert lin.value(0, 0.25) == pytest.approx(0.25)
    assert lin.value(0, 1.5) == pytest.approx(0.75)
    smooth = Curve(keys=keys, interpolation="smooth")
    assert smooth.value(0, 0.25) == pytest.approx(0.25 ** 2 * (3 - 0.5))  # smoothstep
    assert smooth.value(0, 0.5) == pytest.approx(0.5)
    vals = [smooth.value(0, t) for t in np.linspace(0, 2, 201)]
    assert min(vals) >= 0.0 and max(vals) <= 1.0  # no overshoot
    step = Curve(keys=keys, interpolation="step")
    assert step.value(0, 0.99) == 0.0 and step.value(0, 1.0) == 1.0
    per = Curve(per_frame=[0.1, 0.2], normalized=False)
    assert per.value(1, 123.0) == 0.2
    with pytest.raises(ValueError, match="has 2 values"):
        per.value(2, 0.0)


@pytest.mark.parametrize("kwargs,match", [
    (dict(keys=[[0, 0], [0, 1]]), "strictly increasing"),
    (dict(keys=[[0, -1]]), ">= 0"),
    (dict(keys=[[0, 2.0]]), r"\[0, 1\]"),
    (dict(keys=[[0, 0]], per_frame=[0]), "not both"),
    (dict(), "either keys or per_frame"),
    (dict(keys=[[0, 0]], interpolation="cubic"), "interpolation must be"),
    (dict(keys=[0, 1, 2]), r"\[time, value\] pairs"),
])
def test_curve_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Curve(**kwargs)
