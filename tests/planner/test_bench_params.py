"""The decision benchmark runs each mode as its runs do: the mode file's choices over the package defaults."""

from pathlib import Path

import pytest
import yaml

from tactile_planner.bench import mode_params

CONFIG = Path(__file__).resolve().parents[2] / "src" / "tactile_bringup" / "config"


@pytest.mark.parametrize("dim", [2, 3])
def test_decision_benchmark_takes_the_mode_files_choices(dim):
    gpis, planner = mode_params(dim)
    mode_file = yaml.safe_load((CONFIG / f"explore_{dim}d.yaml").read_text())
    want = {**mode_file.get("/**", {}).get("ros__parameters", {}),
            **mode_file.get("soc_planner", {}).get("ros__parameters", {})}
    assert planner["mode"] == gpis["mode"] == f"{dim}d"
    for key, value in want.items():
        if key in planner:
            assert planner[key] == value, key
    assert "start_tip_xyz_m" not in planner  # the explorer's, not declared by the planner
    if dim == 3:
        assert (planner["strategy"], planner["info_travel_per"], planner["clearance"]) == (
            "info_travel", "second", "mean")
