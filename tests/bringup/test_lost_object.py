"""A section the prior misses (the generated letter L: its arms along the workspace's right and bottom
edges, the prior circle over its empty inner corner): the first probes all miss, the estimate loses the
object, and the planner's coverage rings (tactile_planner.search) must find it rather than probe the
prior's centre until the run ends. Oracle: the true section's signed distance (tactile_sim)."""

import numpy as np

from tactile_bringup.experiment import Experiment
from tactile_bringup.loop import ExplorationLoop
from tactile_sim.objects import make_object

OBJECT = "gen2d-005-letter_L"


def test_a_lost_section_is_found_by_the_coverage_rings_and_the_run_goes_on():
    exp = Experiment(mode="2d", object_name=OBJECT, strategy="info_travel", touches=8, seed=0)
    report = ExplorationLoop(exp).run()
    touches = report["touches"]
    assert report["summary"]["stopped_because"] == "touch budget", report["summary"]["stopped_because"]
    outcomes = [t["outcome"] for t in touches]
    assert outcomes[0] == "free_space"  # the prior misses it: the case this test is about
    contacts = np.array([t["contact"][:2] for t in touches if t["outcome"] == "contact"])
    assert len(contacts) >= 2, outcomes
    truth = make_object(OBJECT, mode="2d")
    assert np.abs(truth.sdf(contacts)).max() < 1.5e-3  # real contacts on the true surface
    assert touches[-1]["iou"] > 0.05
