import dataclasses
import tomllib

import pytest

from pipeline.cli import main
from pipeline.config import describe
from pipeline.errors import SceneError
from pipeline.scene import DEFAULT_SCENE_PATH, Scene, load_scene, parse_scene

from .conftest import REFERENCE_SCENE


def _reference_data():
    return tomllib.loads(REFERENCE_SCENE.read_text())


def test_reference_and_default_scenes_load():
    ref = load_scene(REFERENCE_SCENE)
    assert ref.system.pulse_energy_j == 2.5e-6
    assert ref.atmosphere.extinction_per_m == 0.0099
    assert ref.water.extinction_per_m == 0.0199
    default = load_scene(DEFAULT_SCENE_PATH)
    assert default.scene.name == "default"


def test_scene_is_frozen(reference_scene):
    with pytest.raises(dataclasses.FrozenInstanceError):
        reference_scene.system.pulse_energy_j = 1.0


def test_round_trip_through_plain_data(reference_scene):
    # the validated scene, dumped to plain data and validated again, is the same scene
    data = reference_scene.to_dict()
    data["profiler"]["depth_sweep_m"] = list(data["profiler"]["depth_sweep_m"])
    data["profiler"]["shot_counts"] = list(data["profiler"]["shot_counts"])
    assert parse_scene(data) == reference_scene


def _broken(mutate):
    data = _reference_data()
    mutate(data)
    return data


BROKEN = {
    "unknown key (typo)": (
        lambda d: d["system"].update(pulse_energy_J=1e-6),
        r"Unknown key `system.pulse_energy_J`\. Did you mean `system.pulse_energy_j`\?",
    ),
    "wrong type": (
        lambda d: d["water"].update(extinction_per_m="clear"),
        r"`water.extinction_per_m` must be a number; got 'clear'",
    ),
    "out of range": (
        lambda d: d["profiler"].update(altitude_m=-5.0),
        r"`profiler.altitude_m` must be > 0.0; got -5.0",
    ),
    "missing required key": (
        lambda d: d["seabed"].pop("reflectance"),
        r"Missing key `seabed.reflectance` \(Lambertian bottom reflectance\)",
    ),
    "inconsistent keys": (
        lambda d: d["scanner"].update(receiver_fov_mrad=0.5),
        r"`scanner.receiver_fov_mrad` must be >= `scanner.beam_divergence_mrad`",
    ),
    "bad choice of array": (
        lambda d: d["profiler"].update(depth_sweep_m=[10.0, 1.0]),
        r"`profiler.depth_sweep_m` must be \[min, max\] with min < max; got \[10.0, 1.0\]",
    ),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_broken_scenes_give_clear_errors(case):
    mutate, pattern = BROKEN[case]
    with pytest.raises(SceneError, match=pattern):
        parse_scene(_broken(mutate))


def test_broken_scene_messages_are_all_different():
    messages = set()
    for mutate, _ in BROKEN.values():
        with pytest.raises(SceneError) as info:
            parse_scene(_broken(mutate))
        messages.add(str(info.value))
    assert len(messages) == len(BROKEN)


def test_invalid_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[system\npulse_energy_j = 1")
    with pytest.raises(SceneError, match="is not valid TOML"):
        load_scene(bad)
    with pytest.raises(SceneError, match="Scene file not found"):
        load_scene(tmp_path / "nope.toml")


def test_validate_command_exit_status(tmp_path, capsys):
    assert main(["validate", str(REFERENCE_SCENE)]) == 0
    bad = tmp_path / "bad.toml"
    bad.write_text(REFERENCE_SCENE.read_text().replace("altitude_m = 300.0", "altitude_m = -1"))
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "`profiler.altitude_m` must be > 0.0; got -1" in err
    assert "Traceback" not in err


def test_keys_lists_every_field():
    lines = describe(Scene)
    assert any(line.startswith("water.group_index = 1.3638") for line in lines)
    assert any(line.startswith("system.pulse_energy_j = required") for line in lines)
