"""Driving-domain settings and inputs a user may plausibly give: numpy numbers, unusual but
valid settings, mistakes. Each test closes its env: libsumo holds one simulation per process."""

from __future__ import annotations

import numpy as np
import pytest

from sumo_scenarios.env import DrivingConfig, DrivingEnv
from sumo_scenarios.sim import SimConfig


@pytest.mark.parametrize(
    "step", [np.float64(0.25), np.float32(0.25), 0.25], ids=["float64", "float32", "float"]
)
def test_sim_config_takes_numpy_numbers_and_sumo_starts(step):
    # numpy 2's repr of a numpy float ("np.float64(0.25)") was passed to SUMO as the step
    # length: libsumo.start failed with "Invalid Number Format"
    env = DrivingEnv(DrivingConfig(sim=SimConfig(step_length_s=step, ego_start_m=np.int64(300))))
    try:
        obs, info = env.reset(seed=1)
        assert info["step_length_s"] == 0.25 and type(info["step_length_s"]) is float
        env.step(0)
    finally:
        env.close()
    with pytest.raises(ValueError, match="step_length_s must be a number"):
        SimConfig(step_length_s="0.25")
    with pytest.raises(ValueError, match="shift_margin_m must be a number"):
        SimConfig(shift_margin_m=True)
