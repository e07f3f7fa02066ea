"""RobotConfig: defaults from the paper, validation, TOML round trip."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from grfguard.errors import ConfigError
from grfguard.model.robot import JOINT_NAMES, SENSOR_NAMES, SURALP, RobotConfig


def test_suralp_defaults_are_the_papers() -> None:
    r = SURALP
    assert (r.mass, r.upper_leg_length, r.lower_leg_length) == (114.0, 0.28, 0.27)
    assert (r.sole_to_ankle, r.foot_length, r.foot_width) == (0.124, 0.24, 0.15)
    assert len(JOINT_NAMES) == 12 and JOINT_NAMES[0] == "r_hip_yaw"
    assert SENSOR_NAMES == ("r1", "r2", "r3", "r4", "l1", "l2", "l3", "l4")


def test_toml_round_trip_and_edit() -> None:
    text = SURALP.to_toml()
    assert RobotConfig.from_toml(text) == SURALP
    edited = text.replace("mass = 114.0", "mass = 60.0")
    assert RobotConfig.from_toml(edited).mass == 60.0


def test_sensor_layout_order() -> None:
    p = SURALP.sensor_positions_in_foot()
    # 1 front-left, 2 front-right, 3 rear-left, 4 rear-right
    assert p[0, 0] > 0 and p[0, 1] > 0
    assert p[1, 0] > 0 and p[1, 1] < 0
    assert p[2, 0] < 0 and p[2, 1] > 0
    assert p[3, 0] < 0 and p[3, 1] < 0
    np.testing.assert_allclose(p.sum(axis=0), 0.0)


@pytest.mark.parametrize(
    ("key", "value", "needle"),
    [
        ("mass", -3.0, "robot.mass"),
        ("mass", float("nan"), "robot.mass"),
        ("foot_width", 0.5, "hip_width"),
        ("trunk_mass_fraction", 0.5, "add up"),
        ("sensor_inset", 0.2, "robot.sensor_inset"),
    ],
)
def test_impossible_values_fail_with_the_name(key: str, value: float, needle: str) -> None:
    with pytest.raises(ConfigError, match=needle):
        dataclasses.replace(SURALP, **{key: value})


def test_unknown_key_is_named() -> None:
    with pytest.raises(ConfigError, match="masss"):
        RobotConfig.from_dict({"masss": 3})


def test_bad_toml_is_reported(tmp_path) -> None:
    p = tmp_path / "r.toml"
    p.write_text("[robot\nmass = 1")
    with pytest.raises(ConfigError, match="not valid TOML"):
        RobotConfig.from_toml(p)
