"""Tests of the ``--set FIELD=VALUE`` overrides shared by every recipe (refimpl/options.py, spec/cli.md)."""
from __future__ import annotations

import dataclasses

import pytest

from refimpl.errors import UsageError
from refimpl.options import config_with_overrides, parse_overrides


@dataclasses.dataclass(frozen=True)
class _Config:
    hidden: int = 8
    rate: float = 0.5
    velocity: bool = True
    sizes: tuple = (4, 2)
    name: str = "quaternion"

    def __post_init__(self):
        if self.hidden < 1:
            raise ValueError(f"hidden: expected >= 1, got {self.hidden}")


DEFAULTS = dataclasses.asdict(_Config())


def test_values_are_typed_by_the_default():
    out = parse_overrides(_Config, DEFAULTS, ["hidden=16", "rate=1e-3", "sizes=8,4,2", "name=dual_quaternion",
                                              "velocity=false"])
    assert out == {"hidden": 16, "rate": 1e-3, "sizes": (8, 4, 2), "name": "dual_quaternion", "velocity": False}
    assert parse_overrides(_Config, DEFAULTS, []) == {} and parse_overrides(_Config, DEFAULTS, None) == {}


@pytest.mark.parametrize("word, value", [("1", True), ("true", True), ("Yes", True), ("ON", True), (" true ", True),
                                         ("0", False), ("False", False), ("no", False), ("off", False)])
def test_boolean_spellings(word, value):
    assert parse_overrides(_Config, DEFAULTS, [f"velocity={word}"]) == {"velocity": value}


@pytest.mark.parametrize("item, match", [("velocity=maybe", "velocity=maybe"), ("velocity=", "velocity="),
                                         ("hidden=1.5", "not a valid int"), ("rate=fast", "not a valid float"),
                                         ("sizes=4,x", "not a valid tuple"), ("bogus=1", "FIELD one of"),
                                         ("hidden", "expected FIELD=VALUE")])
def test_bad_items_are_usage_errors(item, match):
    """A value of the wrong type is refused with the item named; a boolean is never silently False."""
    with pytest.raises(UsageError, match=match):
        parse_overrides(_Config, DEFAULTS, [item])


def test_config_with_overrides_checks_values_and_fixed_fields():
    base = _Config()
    assert config_with_overrides(base, ["hidden=4", "velocity=off"]) == _Config(hidden=4, velocity=False)
    with pytest.raises(UsageError, match="--set: hidden: expected >= 1"):
        config_with_overrides(base, ["hidden=0"])
    with pytest.raises(UsageError, match="--set name=other: the data decides"):
        config_with_overrides(base, ["name=other"], fixed="name", fixed_note="the data decides")
    assert config_with_overrides(base, ["name=quaternion"], fixed="name") == base  # same value: allowed
