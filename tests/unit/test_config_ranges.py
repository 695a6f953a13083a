"""Every number of the configuration is range-checked, inf and NaN included (E-07; issue 12 finding 1).

TOML and the ISG text lists can both write ``inf`` and ``nan``; a velocity or acceleration without
an upper bound reached the engine as inf (or as values that overflow the interface). The loader
reports each with file, line and key in the usual form.
"""

from __future__ import annotations

import math
from pathlib import Path

import annotated_types
import pytest
from pydantic import BaseModel, ValidationError

import schemas.config as config_models
from schemas.config import AxisConfig, ChannelConfig, DriveModel
from schemas.units import ACCELERATION_LIMIT, VELOCITY_LIMIT_MM_PER_MIN
from tests.unit.config_helpers import errors_of, write


def _models() -> list[type[BaseModel]]:
    return [
        m
        for m in vars(config_models).values()
        if isinstance(m, type) and issubclass(m, BaseModel) and m.__module__ == config_models.__name__
    ]


@pytest.mark.req("E-07")
def test_every_number_of_every_model_has_both_bounds() -> None:
    """No int or float field of the configuration is left open at either end."""
    checked = 0
    for model in _models():
        for name, info in model.model_fields.items():
            if info.annotation not in (int, float):
                continue
            low = [m for m in info.metadata if isinstance(m, annotated_types.Ge | annotated_types.Gt)]
            high = [m for m in info.metadata if isinstance(m, annotated_types.Le | annotated_types.Lt)]
            assert low, f"{model.__name__}.{name} has no lower bound"
            assert high, f"{model.__name__}.{name} has no upper bound"
            checked += 1
    assert checked >= 25  # the introspection found the fields (29 when written)


@pytest.mark.req("E-07")
@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
@pytest.mark.parametrize(
    "field", ["a_emergency", "a_max", "v_max", "v_rapid", "jog_velocity", "jog_acceleration"]
)
def test_inf_and_nan_are_refused_by_the_models(field: str, value: float) -> None:
    with pytest.raises(ValidationError) as info:
        AxisConfig(number=1, name="X", **{field: value})  # type: ignore[arg-type]
    assert info.value.errors()[0]["loc"] == (field,)
    with pytest.raises(ValidationError):
        DriveModel(kv=value)
    with pytest.raises(ValidationError):
        ChannelConfig(axes=["X"], feedhold_deceleration=value)


@pytest.mark.req("E-07")
def test_velocities_and_accelerations_have_sane_upper_bounds() -> None:
    axis = AxisConfig(
        number=1,
        name="X",
        v_max=VELOCITY_LIMIT_MM_PER_MIN,
        v_rapid=VELOCITY_LIMIT_MM_PER_MIN,
        a_max=ACCELERATION_LIMIT,
        a_emergency=ACCELERATION_LIMIT,
    )
    assert axis.v_max == 6_000_000.0
    for field, beyond in (("v_max", 6_000_001.0), ("a_max", 1_000_001.0), ("jog_velocity", 1e300)):
        with pytest.raises(ValidationError, match="less than or equal"):
            AxisConfig(number=1, name="X", **{field: beyond})  # type: ignore[arg-type]


@pytest.mark.req("E-07")
def test_the_loader_names_file_line_and_key_for_inf_nan_and_out_of_range(tmp_path: Path) -> None:
    write(
        tmp_path,
        "y.lis",
        """
        kopf.achs_nr                 2
        getriebe[0].dynamik.a_max    nan
        getriebe[0].dynamik.a_emergency 1e9
        """,
    )
    path = write(
        tmp_path,
        "machine.toml",
        """
        [[axes]]
        number = 1
        name = "X"
        v_max = inf
        a_max = 2e6
        jog_velocity = nan

        [axes.drive]
        kv = -inf

        [[axes]]
        name = "Y"
        parameter_list = "y.lis"

        [[channels]]
        axes = ["X", "Y"]
        main_axes = ["X", "Y", "X"]
        feedhold_deceleration = inf
        """,
    )
    assert errors_of(path) == [
        f"{path}:4: axes[0].v_max: axis X: inf is not a finite number: v_max allows 0 < value ≤ 6000000",
        f"{path}:5: axes[0].a_max: axis X: 2000000.0 is out of range: P-AXIS-00008 allows "
        "1 ≤ value ≤ 1000000",
        f"{path}:6: axes[0].jog_velocity: axis X: nan is not a finite number: jog_velocity allows "
        "0 < value ≤ 6000000",
        f"{path}:9: axes[0].drive.kv: axis X: -inf is not a finite number: kv allows 0 < value ≤ 10000",
        f"{path}:18: channels[0].feedhold_deceleration: channel 1: inf is not a finite number: "
        "feedhold_deceleration allows 0 < value ≤ 1000000",
        f"{tmp_path / 'y.lis'}:2: getriebe[0].dynamik.a_max: nan is not a finite number: P-AXIS-00008 allows "
        "1 ≤ value ≤ 1000000",
        f"{tmp_path / 'y.lis'}:3: getriebe[0].dynamik.a_emergency: 1e9 is out of range: P-AXIS-00003 allows "
        "0 ≤ value ≤ 1000000",
    ]
