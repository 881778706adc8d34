"""The cores each node builds for an experiment, for the offline loop, the explorer and re-analysis.

``make_estimator`` builds what gpis_estimator builds, ``make_planner`` what
soc_planner builds, from the experiment's parameter files. A module of its
own so that the exploration loop and the run recorder (:mod:`.progress`) both
import it without importing each other.
"""

from __future__ import annotations

from tactile_gpis import estimator as gpis_estimator
from tactile_gpis.estimator import ShapeEstimator
from tactile_planner import planner as soc_planner
from tactile_planner.planner import TouchPlanner

from .experiment import Experiment


def _declared(params: dict, table: dict) -> dict:
    """A node ignores the parameters of a file that it does not declare; so do we."""
    return {k: v for k, v in params.items() if k in table}


def make_estimator(experiment: Experiment) -> ShapeEstimator:
    """The estimator the gpis_estimator node builds for this experiment."""
    return ShapeEstimator.from_params(_declared(experiment.gpis_params, gpis_estimator.PARAMETERS))


def make_planner(experiment: Experiment) -> TouchPlanner:
    """The planner the soc_planner node builds for this experiment."""
    params = _declared(experiment.planner_params, soc_planner.PARAMETERS)
    return TouchPlanner.from_params(params, seed=int(experiment.planner_params.get("seed", experiment.seed)))
