"""`bathy keys` tells the truth: every default it prints is the value a run gets."""

import ast

import pytest

from pipeline.config import describe
from pipeline.scene import Scene, parse_scene

# only the keys `bathy keys` marks required, with valid values
MINIMAL = {
    "scene": {"name": "keys"},
    "system": {
        "pulse_energy_j": 1e-3,
        "receiver_efficiency": 0.3,
        "telescope_diameter_m": 0.2,
        "pulse_fwhm_s": 5e-9,
        "filter_bandwidth_nm": 1.0,
    },
    "scanner": {},
    "water": {"extinction_per_m": 0.15},
    "seabed": {"depth_m": 5.0, "reflectance": 0.2},
    "flight": {},
    "profiler": {"altitude_m": 300.0},
}


def _tables(cls, prefix=""):
    """Every nested table of ``cls`` as a dotted path (``process.classify``, ...)."""
    import dataclasses
    import typing

    out = []
    for fld in dataclasses.fields(cls):
        tp = typing.get_type_hints(cls)[fld.name]
        if dataclasses.is_dataclass(tp):
            out.append(prefix + fld.name)
            out += _tables(tp, prefix + fld.name + ".")
    return out


def _with_empty_tables(data):
    """``data`` with every nested table present but empty (keys left out inside it)."""
    data = {k: dict(v) for k, v in data.items()}
    for path in _tables(Scene):
        node = data
        for part in path.split("."):
            node = node.setdefault(part, {})
    return data


def _value(obj, dotted):
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj


def _printed_defaults():
    out = {}
    for line in describe(Scene):
        key, rest = line.split(" = ", 1)
        default = rest.split("  ", 1)[0]
        if "[]" in key or default == "required":
            continue
        out[key] = default
    return out


def _same(printed, value):
    if printed in ("None", "True", "False") or printed[:1] in "'(-0123456789.":
        try:
            return ast.literal_eval(printed) == value
        except ValueError:
            pass
    return printed == str(value)


@pytest.mark.parametrize("how", ["tables left out", "tables given empty"])
def test_every_printed_default_is_the_value_a_run_uses(how):
    data = MINIMAL if how == "tables left out" else _with_empty_tables(MINIMAL)
    scene = parse_scene(data)
    checked = 0
    for key, printed in _printed_defaults().items():
        if key in ("flight", "profiler"):  # given here: tables whose default is None
            continue
        value = _value(scene, key)
        assert _same(printed, value), f"{key}: `bathy keys` says {printed}, the run uses {value!r}"
        checked += 1
    assert checked > 150


def test_a_partly_given_table_keeps_the_other_defaults_of_its_parent():
    # the processing default keeps bottoms from confidence 0.8 (the class alone says 0.5)
    data = dict(MINIMAL, process={"classify": {"min_depth_m": 0.5}})
    scene = parse_scene(data)
    assert scene.process.classify.min_depth_m == 0.5
    assert scene.process.classify.min_confidence == 0.8


def test_keys_lists_optional_and_array_tables():
    keys = {line.split(" = ", 1)[0] for line in describe(Scene)}
    assert {"flight.altitude_m", "profiler.altitude_m", "seabed.features[].size_m"} <= keys
